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
"""

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.smoother import backward_pass, smoother_gain
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, Outcome

__all__ = ['SmoothedRows', 'SmoothingRecorder']

Array = NDArray[np.float64]


class SmoothedRows(NamedTuple):
    """The smoothed estimates of a replay, oldest first: stamps (ns), x (K, n), P (K, n, n)."""

    stamp_ns: NDArray[np.int64]
    x: Array
    P: Array
    segment: NDArray[np.int64]      # which segment (0 first; a reset starts the next)


@dataclass
class _Segment:
    """The forward run of one segment: estimates by stamp and the jumps stepped."""

    predicted: dict[int, tuple[Array, Array]] = field(default_factory=dict)
    corrected: dict[int, tuple[Array, Array]] = field(default_factory=dict)
    sigma: dict[int, int] = field(default_factory=dict)     # point -> next point (ns)


class SmoothingRecorder:
    """Keeps the forward run of a replay from its outcomes; `smoothed()` runs RTS on it."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.kf = config.model.make_filter(config.transition)
        self.n = self.kf.n
        self.segments: list[_Segment] = [_Segment()]

    def outcome(self, out: Outcome) -> None:
        """Take what the session made of a sample or an input (any status)."""
        if out.status == 'reset':
            if self.segments[-1].predicted:
                self.segments.append(_Segment())
        if out.status not in ('accepted', 'inserted', 'reset'):
            return
        seg = self.segments[-1]
        for e in out.estimates:
            kept = seg.predicted if e.kind == 'predicted' else seg.corrected
            kept[e.stamp_ns] = (e.x, e.P)
        for j in out.jumps:
            seg.sigma[j.stamp_ns] = j.sigma_ns

    def smoothed(self) -> SmoothedRows:
        """Return x(t_k|T), P(t_k|T) at every stepped point, segment by segment."""
        parts = [self._smooth(seg) for seg in self.segments if seg.sigma]
        n = self.n
        if not parts:
            return SmoothedRows(np.zeros(0, np.int64), np.zeros((0, n)), np.zeros((0, n, n)),
                                np.zeros(0, np.int64))
        return SmoothedRows(np.concatenate([p[0] for p in parts]),
                            np.concatenate([p[1] for p in parts]),
                            np.concatenate([p[2] for p in parts]),
                            np.concatenate([np.full(len(p[0]), i, np.int64)
                                            for i, p in enumerate(parts)]))

    def _smooth(self, seg: _Segment) -> tuple[NDArray[np.int64], Array, Array]:
        """Smooth one segment's stepped points (the newest, not stepped yet, is left out)."""
        stamps = sorted(seg.sigma)
        K, n = len(stamps), self.n
        x_f, x_p = np.empty((K, n)), np.empty((K, n))
        P_f, P_p, G = np.empty((K, n, n)), np.empty((K, n, n)), np.empty((K, n, n))
        for k, t in enumerate(stamps):
            sigma = seg.sigma[t]
            # x(t_k|t_k): the corrected estimate, or (no measurement) the prediction into t_k
            x_f[k], P_f[k] = seg.corrected.get(t) or seg.predicted[t]
            x_p[k], P_p[k] = seg.predicted[sigma]
            F = self.kf.transition_matrices((sigma - t) / NS)[0]
            G[k] = smoother_gain(P_f[k], np.ascontiguousarray(F), P_p[k])
        xs, Ps = np.empty((K, n)), np.empty((K, n, n))
        backward_pass(x_f, P_f, x_p, P_p, G, 0, K, xs, Ps)
        return np.array(stamps, dtype=np.int64), xs, Ps
