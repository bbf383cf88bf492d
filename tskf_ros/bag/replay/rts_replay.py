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
arrays (stamp, sigma, x(t|t), P(t|t), x(sigma|t), P(sigma|t)), about 1.75 times the
smoothed output at n = 2.  The backward pass writes the output from the newest row back
and frees each chunk of rows as it has used it.
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


@dataclass
class _Rows:
    """Final points of a segment, oldest first: what the backward pass reads."""

    stamp: NDArray[np.int64]
    sigma: NDArray[np.int64]        # the next point (ns)
    x_f: Array                      # x(t|t), P(t|t)
    P_f: Array
    x_p: Array                      # x(sigma|t), P(sigma|t)
    P_p: Array


@dataclass
class _Segment:
    """The forward run of one segment: the newest estimates by stamp, older ones as rows."""

    predicted: dict[int, tuple[Array, Array]] = field(default_factory=dict)
    corrected: dict[int, tuple[Array, Array]] = field(default_factory=dict)
    sigma: dict[int, int] = field(default_factory=dict)     # point -> next point (ns)
    rows: list[_Rows] = field(default_factory=list)
    final: Optional[int] = None     # the newest stamp in rows

    @property
    def points(self) -> int:
        """Return the number of stepped points."""
        return len(self.sigma) + sum(r.stamp.size for r in self.rows)


class SmoothingRecorder:
    """Keeps the forward run of a replay from its outcomes; `smoothed()` runs RTS on it."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.kf = config.model.make_filter(config.transition)
        self.n = self.kf.n
        self.segments: list[_Segment] = [_Segment()]
        # points a late sample may still revise: those of the session's history, with room
        self.live = 4 * config.history_size + CHUNK
        self._result: Optional[tuple[SmoothedRows, NDArray[np.int64]]] = None

    def outcome(self, out: Outcome) -> None:
        """Take what the session made of a sample or an input (any status)."""
        if out.status == 'reset':
            if self.segments[-1].predicted or self.segments[-1].rows:
                self._freeze(self.segments[-1], len(self.segments[-1].sigma))
                self.segments.append(_Segment())
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
        """Make the `count` oldest stepped points of seg final: rows of arrays."""
        stamps = sorted(seg.sigma)[:count]
        if not stamps:
            return
        K, n = len(stamps), self.n
        rows = _Rows(np.array(stamps, dtype=np.int64), np.empty(K, np.int64),
                     np.empty((K, n)), np.empty((K, n, n)), np.empty((K, n)),
                     np.empty((K, n, n)))
        for k, t in enumerate(stamps):
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
        seg.rows.append(rows)
        seg.final = last

    def smoothed(self) -> SmoothedRows:
        """Return x(t_k|T), P(t_k|T) at every stepped point, segment by segment."""
        return self.smoothed_rows()[0]

    def smoothed_rows(self) -> tuple[SmoothedRows, NDArray[np.int64]]:
        """
        Return smoothed() and each row's next point sigma (ns).

        The rows kept are freed as they are smoothed: the result is made once, and kept.
        """
        if self._result is not None:
            return self._result
        segments = [seg for seg in self.segments if seg.sigma or seg.rows]
        for seg in segments:
            self._freeze(seg, len(seg.sigma))
        K, n = sum(seg.points for seg in segments), self.n
        out = SmoothedRows(np.empty(K, np.int64), np.empty((K, n)), np.empty((K, n, n)),
                           np.empty(K, np.int64))
        sigma = np.empty(K, np.int64)
        end = K
        for i in range(len(segments) - 1, -1, -1):
            seg = segments[i]
            start = end - seg.points
            out.segment[start:end] = i
            self._smooth(seg, out, sigma, start, end)
            end = start
        self.segments = []
        self._result = out, sigma
        return self._result

    def _smooth(self, seg: _Segment, out: SmoothedRows, sigma: NDArray[np.int64], start: int,
                end: int) -> None:
        """Smooth one segment's rows into out[start:end], newest chunk first, freeing each."""
        last = end                  # the segment's newest point is row last - 1
        while seg.rows:
            rows = seg.rows.pop()
            K = rows.stamp.size
            a, b = end - K, end
            out.stamp_ns[a:b] = rows.stamp
            sigma[a:b] = rows.sigma
            G = np.empty((K, self.n, self.n))
            for k in range(K):
                F = self.kf.transition_matrices((int(rows.sigma[k]) - int(rows.stamp[k]))
                                                / NS)[0]
                G[k] = smoother_gain(rows.P_f[k], np.ascontiguousarray(F), rows.P_p[k])
            x_f, P_f, count = rows.x_f, rows.P_f, K
            if b < last:
                # the next point, smoothed already, closes this chunk: the x(T|T) of its pass
                x_f = np.concatenate([x_f, out.x[b:b + 1]])
                P_f = np.concatenate([P_f, out.P[b:b + 1]])
                count = K + 1
            backward_pass(x_f, P_f, rows.x_p, rows.P_p, G, 0, count, out.x[a:a + count],
                          out.P[a:a + count])
            end = a
