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
Fixed-lag smoother for the time-scale Kalman filter: x(t_{k-L}|t_k) as each point t_k arrives.

A window of the L + 1 newest points, fed one filter `StepResult` (and its jump F) at a
time; once full, each new point runs the RTS backward step of `tskf_ros.core.smoother`
(Rauch, Tung & Striebel 1965; Sarkka 2013, Theorem 8.2) from x(t_k|t_k) down to the
oldest point.  The output is delayed by L points: t_k - t_{k-L} = mu_{k-L} + ... + mu_{k-1}.
"""

import math
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.matrices import as_matrix, FilterError
from tskf_ros.core.smoother import backward_pass, smoother_gain
from tskf_ros.core.timescale_kalman import StepResult

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['FixedLagSmoother', 'Lagged']


class Lagged(NamedTuple):
    """The smoothed estimate of one point, given the points up to the newest."""

    point: int      # the point's number: 0 for the first StepResult added
    delay: float    # t_newest - t_point, the sum of the graininesses in between
    x: Vector       # x(t_point|t_newest)
    P: Matrix       # P(t_point|t_newest)


class FixedLagSmoother:
    """
    RTS smoothing over a sliding window of L + 1 points of a TimeScaleKalmanFilter run.

    A node that runs the filter step by step adds every result::

        res = kf.step(mu, y)
        F, _, _ = kf.transition_matrices(mu)
        out = smoother.add(res, F)        # None until L + 1 points have been added

    `out` is the estimate of the point L back, equal to the full `rts_smooth` over the
    points added so far.  The window is a ring of L + 1 rows: memory O(L), time per
    point O(L) backward steps.  `flush` gives the last L points at the end of a stream.
    """

    def __init__(self, lag: int) -> None:
        if isinstance(lag, bool) or not isinstance(lag, (int, np.integer)) or lag < 0:
            raise FilterError(f'lag must be a whole number of points >= 0, got {lag!r}')
        self.lag = int(lag)
        self._added = 0         # points added; the newest is point _added - 1
        self._count = 0         # points in the window
        self._n = 0             # state dimension, set by the first add

    def __len__(self) -> int:
        """Return the number of points in the window."""
        return self._count

    def _allocate(self, n: int) -> None:
        """Make the ring of L + 1 rows for n states, and the backward pass's output."""
        cap = self.lag + 1
        self._n = n
        self._mu = np.zeros(cap)
        self._x_f, self._x_p, self._xs = np.empty((3, cap, n))
        self._P_f, self._P_p, self._G, self._Ps = np.empty((4, cap, n, n))

    def add(self, result: StepResult, F: ArrayLike) -> Optional[Lagged]:
        """
        Add the filter's step at the newest point and its jump F (I + mu A or e^{A mu}).

        Return the smoothed estimate of the point `lag` back, or None while fewer than
        lag + 1 points have been added.
        """
        n = result.x_corrected.shape[0]
        if self._n and n != self._n:
            raise FilterError(f'the step has {n} states, the window {self._n}')
        # C order, the layout the kernels are compiled for (e^{A mu} may come transposed)
        F_ = np.ascontiguousarray(as_matrix(F, 'F'))
        if F_.shape != (n, n):
            raise FilterError(f'F must have shape {(n, n)} to match the step, got {F_.shape}')
        mu = float(result.mu)
        if not (math.isfinite(mu) and mu > 0):
            raise FilterError(f'the step has mu = {mu}: a graininess must be finite and > 0')
        if not self._n:
            self._allocate(n)
        cap = self.lag + 1
        row = self._added % cap
        self._mu[row] = mu
        self._x_f[row], self._P_f[row] = result.x_corrected, result.P_corrected
        self._x_p[row], self._P_p[row] = result.x_predicted, result.P_predicted
        # the gain of the jump from this point, used once a later point arrives
        self._G[row] = smoother_gain(self._P_f[row], F_, self._P_p[row])
        self._added += 1
        self._count = min(self._count + 1, cap)
        if self._count < cap:
            return None
        first = self._smooth()
        # t_newest - t_first: every graininess in the window but the newest's
        delay = float(np.sum(self._mu)) - mu
        return Lagged(first, delay, self._xs[0].copy(), self._Ps[0].copy())

    def flush(self) -> list[Lagged]:
        """Return the points not yet output, oldest first, smoothed on the window; empty it."""
        if not self._count:
            return []
        cap, count = self.lag + 1, self._count
        first = self._smooth()
        mus = self._mu[[(first + i) % cap for i in range(count)]]
        # t_newest - t_k: the graininesses of point k up to the one before the newest
        delays = np.cumsum(mus[::-1])[::-1] - mus[-1]
        # a full window has output its oldest point already
        done = 1 if count == cap else 0
        self._count = 0
        return [Lagged(first + i, float(delays[i]), self._xs[i].copy(), self._Ps[i].copy())
                for i in range(done, count)]

    def _smooth(self) -> int:
        """Run the backward pass over the window into _xs, _Ps; return the oldest point."""
        first = self._added - self._count
        backward_pass(self._x_f, self._P_f, self._x_p, self._P_p, self._G,
                      first % (self.lag + 1), self._count, self._xs, self._Ps)
        return first
