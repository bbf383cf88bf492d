# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Time scales: forward jump, graininess, the papers' time scales, and a gap classifier.

Definitions (Bohner & Wintz Definition 2.3; Cai et al. Definition 2):
    sigma(t) = inf{s in T : s > t},   mu(t) = sigma(t) - t,
    rho(t) = sup{s in T : s < t},     nu(t) = t - rho(t)   (backward graininess).

Builders: Bohner & Wintz Table 4 and Example 2.2 (hZ, q^Z, N_0^2, {H_n}, P_{a,b}), Example
3.20 / Cai Section III-B (T_3), Cai Section IV-C (T_d).  How a dense stretch is realised:
doc/design/core.md.
"""

from dataclasses import dataclass
from typing import Iterable, Literal, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

Points = NDArray[np.float64]
# a piece of a time scale to build: ('dense', a, b) is [a, b]; ('discrete', points) isolated
DenseStretch = tuple[Literal['dense'], float, float]
IsolatedPoints = tuple[Literal['discrete'], ArrayLike]
Piece = Union[DenseStretch, IsolatedPoints]


class TimeScaleError(ValueError):
    """A time scale or a stream of stamps that cannot be used as given."""


@dataclass(frozen=True)
class TimeScale:
    """Sorted points of a time scale; dense[i] says [t_i, t_i+1] realises a dense stretch."""

    points: Points
    dense: NDArray[np.bool_]

    def __post_init__(self) -> None:
        """Check the points are finite and strictly increasing."""
        pts = np.asarray(self.points, dtype=float)
        dense = np.asarray(self.dense, dtype=bool)
        if pts.ndim != 1 or pts.size == 0:
            raise TimeScaleError('a time scale needs a non-empty 1-D array of points')
        if not np.all(np.isfinite(pts)):
            raise TimeScaleError('time scale points must be finite')
        if np.any(np.diff(pts) <= 0):
            i = int(np.argmin(np.diff(pts)))
            raise TimeScaleError(f'time scale points must increase strictly: '
                                 f't[{i}] = {pts[i]}, t[{i + 1}] = {pts[i + 1]}')
        if dense.shape != (max(pts.size - 1, 0),):
            raise TimeScaleError(f'dense needs one flag per interval ({pts.size - 1}), '
                                 f'got {dense.shape}')
        object.__setattr__(self, 'points', pts)
        object.__setattr__(self, 'dense', dense)

    def __len__(self) -> int:
        """Return the number of points."""
        return self.points.size

    def sigma(self) -> Points:
        """Return the forward jump at each point (the last point jumps to itself)."""
        return forward_jump(self.points)

    def mu(self) -> Points:
        """Graininess of the realised points (the step a filter takes; 0 at max T)."""
        return graininess(self.points)

    def nu(self) -> Points:
        """Backward graininess (0 at min T)."""
        return backward_graininess(self.points)

    def mu_theory(self) -> Points:
        """Graininess of the time scale itself: 0 on dense stretches, the jump elsewhere."""
        m = self.mu()
        m[:-1][self.dense] = 0.0
        return m

    def until(self, t_max: float) -> 'TimeScale':
        """Return the part with t <= t_max."""
        k = int(np.searchsorted(self.points, t_max, side='right'))
        return TimeScale(self.points[:k], self.dense[:max(k - 1, 0)])

    def head(self, count: int) -> 'TimeScale':
        """Return the first count points."""
        return TimeScale(self.points[:count], self.dense[:max(count - 1, 0)])


def forward_jump(points: ArrayLike) -> Points:
    """sigma(t_i) = t_{i+1}; sigma(max T) = max T."""
    t = np.asarray(points, dtype=float)
    return np.append(t[1:], t[-1])


def graininess(points: ArrayLike) -> Points:
    """mu(t_i) = t_{i+1} - t_i; mu(max T) = 0."""
    t = np.asarray(points, dtype=float)
    return forward_jump(t) - t


def backward_graininess(points: ArrayLike) -> Points:
    """nu(t_i) = t_i - t_{i-1}; nu(min T) = 0."""
    t = np.asarray(points, dtype=float)
    return t - np.insert(t[:-1], 0, t[0])


def discrete(points: Iterable[float]) -> TimeScale:
    """Build a time scale of isolated points only (no dense stretch)."""
    pts = np.asarray(sorted(points), dtype=float)
    return TimeScale(pts, np.zeros(max(pts.size - 1, 0), dtype=bool))


def h_integers(h: float, count: int, start: float = 0.0) -> TimeScale:
    """hZ: start, start + h, ... (count points); mu = h (Table 4)."""
    if h <= 0:
        raise TimeScaleError(f'h must be > 0, got {h}')
    return discrete(start + h * np.arange(count))


def harmonic(count: int, first: int = 0) -> TimeScale:
    """{H_n}: H_n = sum_{k=1}^n 1/k for n = first, ..., first + count - 1; mu(H_n) = 1/(n+1)."""
    n = np.arange(first + count)
    h = np.concatenate([[0.0], np.cumsum(1.0 / n[1:])])
    return discrete(h[first:])


def q_integers(q: float, k_min: int, k_max: int) -> TimeScale:
    """q^Z points q^k, k = k_min..k_max (q > 1); mu(t) = (q - 1) t (Table 4)."""
    if q <= 1:
        raise TimeScaleError(f'q must be > 1, got {q}')
    return discrete(q ** np.arange(k_min, k_max + 1, dtype=float))


def squares(count: int) -> TimeScale:
    """N_0^2 = {0, 1, 4, 9, ...}; mu(t) = 1 + 2 sqrt(t) (Table 4)."""
    return discrete(np.arange(count, dtype=float) ** 2)


def from_segments(segments: Sequence[Piece], dense_step: float) -> TimeScale:
    """
    Build a time scale from ('dense', a, b) and ('discrete', [points]) segments.

    A dense segment [a, b] is realised as a, a + h, ..., b with h <= dense_step
    chosen so that b is hit exactly.  Whether the paper writes an end open or closed
    does not change a finite realisation: the neighbouring point closes it.
    """
    if not dense_step > 0:
        raise TimeScaleError(f'dense_step must be > 0, got {dense_step}')
    pts: list[Points] = []
    dense_spans: list[tuple[float, float]] = []
    for seg in segments:
        if seg[0] == 'dense':
            a, b = float(seg[1]), float(seg[2])
            k = max(1, int(np.ceil((b - a) / dense_step - 1e-9)))
            pts.append(np.linspace(a, b, k + 1))
            dense_spans.append((a, b))
        elif seg[0] == 'discrete':
            pts.append(np.asarray(seg[1], dtype=float))
        else:
            raise TimeScaleError(f'unknown segment kind {seg[0]!r}')
    joined = np.concatenate(pts)
    t = np.unique(np.round(joined, 9))
    left, right = t[:-1], t[1:]
    dense = np.zeros(left.size, dtype=bool)
    for a, b in dense_spans:
        dense |= (left >= a - 1e-9) & (right <= b + 1e-9)
    return TimeScale(t, dense)


def p_ab(a: float, b: float, periods: int, dense_step: float) -> TimeScale:
    """P_{a,b} = union_k [k c, k c + a], c = a + b, for k = 0..periods-1 (Table 4)."""
    c = a + b
    return from_segments([('dense', k * c, k * c + a) for k in range(periods)], dense_step)


def concatenate(first: TimeScale, second: TimeScale, switch: float) -> TimeScale:
    """Join two time scales: first for t <= switch, second for t > switch (Cai's T_3)."""
    a = first.until(switch)
    k = int(np.searchsorted(second.points, switch, side='right'))
    b = TimeScale(second.points[k:], second.dense[k:] if k < second.points.size else
                  np.zeros(0, dtype=bool))
    if b.points.size == 0:
        return a
    return TimeScale(np.concatenate([a.points, b.points]),
                     np.concatenate([a.dense, [False], b.dense]))


def cai_t3(count: int) -> TimeScale:
    """Cai's T_3 / Bohner & Wintz's fourth case: 2Z for t <= 8, {H_n} for t > 8; count points."""
    two_z = h_integers(2.0, 5)                       # 0, 2, 4, 6, 8
    # H_n passes 8 near n = 1674; build enough of {H_n} beyond it
    first = int(np.searchsorted(np.cumsum(1.0 / np.arange(1, 4000)), 8.0, side='right')) + 1
    return concatenate(two_z, harmonic(count, first=first), 8.0).head(count)


# Cai et al. Section IV-C: T_d = [1,15) u {15..21} u (21,30] u [32,62) u {62..67} u (67,75)
# u {75..81} u (81,83) u {83..86} u (86,126] u [128,131] u {135..154} u (154,173)
# u {173..204} u (204,209] u [212,218] u {224..238} u (238,273) u {273..285} u (285,300]
CAI_TD_SEGMENTS: tuple[Piece, ...] = (
    ('dense', 1, 15), ('discrete', range(15, 22)), ('dense', 21, 30),
    ('dense', 32, 62), ('discrete', range(62, 68)), ('dense', 67, 75),
    ('discrete', range(75, 82)), ('dense', 81, 83), ('discrete', range(83, 87)),
    ('dense', 86, 126), ('dense', 128, 131), ('discrete', range(135, 155)),
    ('dense', 154, 173), ('discrete', range(173, 205)), ('dense', 204, 209),
    ('dense', 212, 218), ('discrete', range(224, 239)), ('dense', 238, 273),
    ('discrete', range(273, 286)), ('dense', 285, 300),
)
# The five jumps of Fig. 6(b): (point after the jump, J)
CAI_TD_JUMPS = ((32.0, 2.0), (128.0, 2.0), (135.0, 4.0), (212.0, 3.0), (224.0, 6.0))


def cai_td(dense_step: float = 0.1) -> TimeScale:
    """Cai's T_d (Section IV-C) with dense parts realised at dense_step seconds."""
    return from_segments(CAI_TD_SEGMENTS, dense_step)


@dataclass(frozen=True)
class Segment:
    """A run of a stamp stream: 'dense', 'discrete' or 'jump', from start to end."""

    kind: str
    start: float
    end: float
    count: int        # points in the run (for a jump: 0, it has only its two ends)

    @property
    def length(self) -> float:
        """Return end - start; for a jump this is J."""
        return self.end - self.start


def classify(stamps: ArrayLike, *, period: float, dense_fraction: float = 0.5,
             jump_factor: float = 1.5) -> list[Segment]:
    """
    Split sorted stamps into dense runs, discrete runs and jumps (gaps), from data.

    An interval dt between neighbours is dense when dt < dense_fraction * period,
    discrete when it is up to jump_factor * period, and a jump (a gap of length
    J = dt) beyond that.  `period` is the nominal sampling period of the discrete
    parts (1 s for Cai's power meter).  Consecutive intervals of one kind form a run.
    """
    t = np.asarray(stamps, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise TimeScaleError('classify needs at least two stamps')
    if not period > 0:
        raise TimeScaleError(f'period must be > 0, got {period}')
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise TimeScaleError('stamps must increase strictly')
    kind = np.where(dt < dense_fraction * period, 'dense',
                    np.where(dt <= jump_factor * period, 'discrete', 'jump'))
    out: list[Segment] = []
    i = 0
    while i < dt.size:
        j = i
        while kind[i] != 'jump' and j + 1 < dt.size and kind[j + 1] == kind[i]:
            j += 1
        k = str(kind[i])
        out.append(Segment(k, float(t[i]), float(t[j + 1]), 0 if k == 'jump' else j - i + 2))
        i = j + 1
    return out


def jumps(stamps: ArrayLike, *, period: float,
          jump_factor: float = 1.5) -> list[tuple[float, float]]:
    """(point after the jump, J) for every gap longer than jump_factor * period."""
    return [(s.end, s.length) for s in classify(stamps, period=period, jump_factor=jump_factor)
            if s.kind == 'jump']
