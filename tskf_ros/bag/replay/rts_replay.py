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
Offline RTS smoothing of a replay: x(t_k|T), P(t_k|T) at the session's points, per segment.

The forward pass is the session's own run (its `kf.step` at every point, revised by late
samples), read from the outcomes: x(t_k|t_k), P(t_k|t_k) (the corrected estimate, or for
an input-only point the prediction into it), x(t_{k+1}|t_k), P(t_{k+1}|t_k) and mu_k.  The
backward pass is `tskf_ros.core.smoother`'s (Rauch, Tung & Striebel 1965; Sarkka 2013,
Theorem 8.2) with F_k = I + mu_k A or e^{A mu_k}.  A reset starts a new segment from x0, P0;
each segment is smoothed on its own.  See doc/design/smoother.md.

Memory: the newest points (those a late sample may still revise: a few times the
session's history_size) are kept by stamp; older ones are final and are kept as rows of
columns grown in place (stamp, sigma, segment, x(t|t), P(t|t), x(sigma|t), P(sigma|t)),
15 + 2 n + 2 n^2 numbers a point against the output's 2 + n + n^2: 1.75x at n = 1, 1.9x
at n = 2.  The backward pass smooths x(t|t), P(t|t) in place, a chunk at a time from the
newest point, and the output is those columns.
"""

from dataclasses import dataclass, field
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.smoother import backward_pass, smoother_gain
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, Outcome

__all__ = ['SmoothedRows', 'SmoothingRecorder']

Array = NDArray[np.float64]
# points made final into rows of arrays at a time
CHUNK = 4096


class SmoothedRows(NamedTuple):
    """The smoothed estimates of a replay, oldest first: stamps (ns), x (K, n), P (K, n, n)."""

    stamp_ns: NDArray[np.int64]
    x: Array
    P: Array
    segment: NDArray[np.int64]      # which segment (0 first; a reset starts the next)


class _Rows:
    """
    The final points, oldest first (segment by segment), as columns grown in place.

    stamp, sigma (the next point, ns), segment; x(t|t), P(t|t); x(sigma|t), P(sigma|t).
    ndarray.resize grows an array in place (a large one by remapping its pages), so the
    memory held is the rows written, not the room made.
    """

    def __init__(self, n: int) -> None:
        self.count = 0
        self.stamp, self.sigma, self.segment = (np.empty(0, np.int64) for _ in range(3))
        self.x_f, self.x_p = np.empty((0, n)), np.empty((0, n))
        self.P_f, self.P_p = np.empty((0, n, n)), np.empty((0, n, n))

    def columns(self) -> tuple[np.ndarray, ...]:
        """Return the columns."""
        return self.stamp, self.sigma, self.segment, self.x_f, self.P_f, self.x_p, self.P_p

    def grow(self, k: int) -> slice:
        """Make room for k more rows; return their slice."""
        need = self.count + k
        if need > self.stamp.shape[0]:
            size = max(need, self.stamp.shape[0] * 3 // 2, CHUNK)
            for arr in self.columns():
                arr.resize((size, *arr.shape[1:]), refcheck=False)
        rows = slice(self.count, need)
        self.count = need
        return rows

    def trim(self) -> None:
        """Shrink every column to the rows written."""
        for arr in self.columns():
            arr.resize((self.count, *arr.shape[1:]), refcheck=False)


@dataclass
class _Segment:
    """The newest points of a segment by stamp (the older ones are rows)."""

    index: int                      # 0 first; a reset starts the next
    predicted: dict[int, tuple[Array, Array]] = field(default_factory=dict)
    corrected: dict[int, tuple[Array, Array]] = field(default_factory=dict)
    sigma: dict[int, int] = field(default_factory=dict)     # point -> next point (ns)
    final: Optional[int] = None     # the newest stamp in the rows
    start: int = -1                 # its first row (-1: none yet)


class SmoothingRecorder:
    """Keeps the forward run of a replay from its outcomes; `smoothed()` runs RTS on it."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.kf = config.model.make_filter(config.transition)
        self.n = self.kf.n
        self.segments: list[_Segment] = [_Segment(0)]
        self.rows = _Rows(self.n)
        # points a late sample may still revise: those of the session's history, with room
        self.live = 4 * config.history_size + CHUNK
        self._result: Optional[tuple[SmoothedRows, NDArray[np.int64]]] = None

    def outcome(self, out: Outcome) -> None:
        """Take what the session made of a sample or an input (any status)."""
        if out.status == 'reset':
            seg = self.segments[-1]
            if seg.predicted or seg.start >= 0:
                self._freeze(seg, len(seg.sigma))
                self.segments.append(_Segment(seg.index + (seg.start >= 0)))
        if out.status not in ('accepted', 'inserted', 'reset'):
            return
        seg = self.segments[-1]
        for e in out.estimates:
            self._check(seg, e.stamp_ns)
            kept = seg.predicted if e.kind == 'predicted' else seg.corrected
            kept[e.stamp_ns] = (e.x, e.P)
        for j in out.jumps:
            self._check(seg, j.stamp_ns)
            seg.sigma[j.stamp_ns] = j.sigma_ns
        if len(seg.sigma) >= self.live + CHUNK:
            self._freeze(seg, CHUNK)

    @staticmethod
    def _check(seg: _Segment, stamp_ns: int) -> None:
        """Refuse a revision of a point already final (older than the session's history)."""
        if seg.final is not None and stamp_ns <= seg.final:
            raise RuntimeError(f'the smoother was sent an estimate at {stamp_ns} ns, at or '
                               f'before a point it had made final ({seg.final} ns)')

    def _freeze(self, seg: _Segment, count: int) -> None:
        """Make the `count` oldest stepped points of seg final: rows."""
        stamps = sorted(seg.sigma)[:count]
        if not stamps:
            return
        rows = self.rows
        at = rows.grow(len(stamps))
        if seg.start < 0:
            seg.start = at.start
        rows.stamp[at] = stamps
        rows.segment[at] = seg.index
        for k, t in enumerate(stamps, at.start):
            sigma = rows.sigma[k] = seg.sigma.pop(t)
            # x(t_k|t_k): the corrected estimate, or (no measurement) the prediction into t_k
            rows.x_f[k], rows.P_f[k] = seg.corrected.get(t) or seg.predicted[t]
            rows.x_p[k], rows.P_p[k] = seg.predicted[sigma]
        # what is older than the newest final point is read no more (its sigma's prediction
        # may be the next point's x(t|t))
        last = stamps[-1]
        for kept in (seg.predicted, seg.corrected):
            for t in [t for t in kept if t <= last]:
                del kept[t]
        seg.final = last

    def smoothed(self) -> SmoothedRows:
        """Return x(t_k|T), P(t_k|T) at every stepped point, segment by segment."""
        return self.smoothed_rows()[0]

    def smoothed_rows(self) -> tuple[SmoothedRows, NDArray[np.int64]]:
        """
        Return smoothed() and each row's next point sigma (ns).

        The smoothing is done in place over the rows kept: the result is made once, and kept.
        """
        if self._result is not None:
            return self._result
        for seg in self.segments:
            self._freeze(seg, len(seg.sigma))
        rows = self.rows
        rows.trim()
        starts = [seg.start for seg in self.segments if seg.start >= 0] + [rows.count]
        for a, b in zip(starts[:-1], starts[1:]):
            self._smooth(a, b)
        self._result = (SmoothedRows(rows.stamp, rows.x_f, rows.P_f, rows.segment), rows.sigma)
        self.segments, self.rows = [], _Rows(self.n)
        return self._result

    def _smooth(self, start: int, end: int) -> None:
        """Smooth rows start..end-1 (one segment) in place, a chunk at a time from the newest."""
        rows, n = self.rows, self.n
        b = end - 1                 # the newest point: x(T|T) is its x(t|t)
        while b > start:
            a = max(start, b - CHUNK)
            G = np.empty((b - a, n, n))
            for k in range(a, b):
                F = self.kf.transition_matrices((int(rows.sigma[k]) - int(rows.stamp[k]))
                                                / NS)[0]
                G[k - a] = smoother_gain(rows.P_f[k], np.ascontiguousarray(F), rows.P_p[k])
            # rows a..b: row b is smoothed already (the x(T|T) of this pass); the pass reads
            # each row's x(t|t) before it writes its x(t|T) there
            backward_pass(rows.x_f[a:b + 1], rows.P_f[a:b + 1], rows.x_p[a:b],
                          rows.P_p[a:b], G, 0, b + 1 - a, rows.x_f[a:b + 1],
                          rows.P_f[a:b + 1])
            b = a
