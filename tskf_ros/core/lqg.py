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
The LQG controller on a time scale (Bohner & Wintz 2013, Remark 4.2, eq. (29)-(31)).

    x^Delta = A x + B u + G w,   y = C x + v,
    J = E[1/2 x(t_f)^T F x(t_f) + 1/2 int (x^T M x + u^T N u) Delta tau]       (29)
    xhat^Delta = A xhat + B u + K [y - C xhat],   u = -L xhat                 (30)

K is the Kalman gain of Table 3 (TimeScaleKalmanFilter), L the LQR gain (8) of the
sweep (7) with weights M, N, F (TimeScaleLQR): designed apart (separation, (31)).
estimate='corrected' feeds back x(t|t), the filter's measurement update at t, instead of
the predictor xhat(t) of (30).  The expected cost, from completing the square along (7):

    J = 1/2 [xbar0^T S_0 xbar0 + tr(S_0 P_0) + sum_k mu_k tr(S_{k+1} G Q G^T)
             + sum_k mu_k tr(L_k^T (N + mu_k B^T S_{k+1} B) L_k E_k)]

with E_k the covariance of the error of the estimate fed back (P(t_k) predicted, or
P(t_k|t_k)).  Derivation: doc/design/lqr.md.
"""

import copy
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.lqr import LQRError, LQRGains, TimeScaleLQR
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['ESTIMATES', 'TimeScaleLQG']

ESTIMATES = ('predicted', 'corrected')


class TimeScaleLQG:
    """
    Remark 4.2 over a time scale known in advance (right-scattered points t_0..t_K).

    `step(y)` takes y(t_k) and returns u(t_k) = -L_k xhat (the estimate chosen by
    `estimate`), then moves the filter to t_{k+1} with that input.  The filter and the
    regulator are public (`filter`, `regulator`, `plan`).
    """

    def __init__(self, A: ArrayLike, B: ArrayLike, C: ArrayLike, *, M: ArrayLike,
                 N: ArrayLike, Q: ArrayLike, R: ArrayLike, mu: ArrayLike,
                 F: Optional[ArrayLike] = None, G: Optional[ArrayLike] = None,
                 x0: ArrayLike, P0: ArrayLike, estimate: str = 'predicted') -> None:
        if estimate not in ESTIMATES:
            raise LQRError(f'estimate must be one of {ESTIMATES}, got {estimate!r}')
        self.estimate = estimate
        self.regulator = TimeScaleLQR(A, B, M, N, F)
        self.mu = np.array(mu, dtype=float).reshape(-1)
        # a dense stretch would need the filter and the feedback integrated together
        self.plan: LQRGains = self.regulator.gains(self.mu)
        self.filter = TimeScaleKalmanFilter(A, C, Q=Q, R=R, G=G, B=B, x0=x0, P0=P0)
        self.x0 = self.filter.x.copy()
        self.P0 = self.filter.P.copy()
        self.k = 0

    def reset(self) -> None:
        """Go back to t_0 with the initial estimate (for another run of the same plan)."""
        self.filter.set_state(self.x0, self.P0)
        self.k = 0

    @property
    def steps(self) -> int:
        """Return the number of steps K of the horizon."""
        return int(self.mu.size)

    def step(self, y: ArrayLike) -> Vector:
        """Take y(t_k); return u(t_k) and move the filter to t_{k+1} (Remark 4.2, (30))."""
        k = self.k
        if k >= self.steps:
            raise LQRError(f'the horizon has {self.steps} steps; all are used')
        mu, L = float(self.mu[k]), self.plan.L[k]
        if self.estimate == 'predicted':
            # (30): u = -L xhat with the predictor xhat(t_k)
            u = -L @ self.filter.x
            self.filter.step(mu, y, u)
        else:
            res = self.filter.step(mu, y, None)
            # u = -L x(t_k|t_k)
            u = -L @ res.x_corrected
            # the prediction without input plus B_d u: x(sigma) = F x(t|t) + B_d u
            _, _, Bd = self.filter.transition_matrices(mu)
            self.filter.x = self.filter.x + Bd @ u
        self.k = k + 1
        return u

    def error_covariances(self) -> NDArray[np.float64]:
        """Return the covariance of the fed-back estimate's error at t_0..t_{K-1}."""
        probe = copy.deepcopy(self.filter)
        probe.set_state(self.x0, self.P0)
        out = np.empty((self.steps, probe.n, probe.n))
        zero = np.zeros(probe.p)
        for k, mu in enumerate(self.mu):
            P_predicted = probe.P
            res = probe.step(float(mu), zero)
            out[k] = res.P_corrected if self.estimate == 'corrected' else P_predicted
        return out

    def expected_cost(self) -> float:
        """Return J of (29) under this controller, from the sweep and the filter's P."""
        S, L = self.plan.S, self.plan.L
        B, N = self.regulator.B, self.regulator.R
        GQGt = self.filter.GQGt
        E = self.error_covariances()
        J = float(self.x0 @ S[0] @ self.x0 + np.trace(S[0] @ self.P0))
        for k, mu in enumerate(self.mu):
            Lam = mu * (N + mu * (B.T @ S[k + 1] @ B))
            J += float(mu * np.trace(S[k + 1] @ GQGt) + np.trace(L[k].T @ Lam @ L[k] @ E[k]))
        return J / 2
