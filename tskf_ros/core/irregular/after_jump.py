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
The time-scale filter's covariance around one jump of length J in a steady stream.

Not in the papers: with points every h in the steady state of Bohner & Wintz Table 3, one
point t* is followed by t* + J; P_peak = F_J P(t*|t*) F_J^T + Q_d(J) is Fang & de
Callafon's peak covariance for that gap, and the recovery counts the nominal steps back.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import kalman
from tskf_ros.core.irregular.common import interval, IrregularError
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.core.transitions import van_loan

Matrix = NDArray[np.float64]


@dataclass(frozen=True)
class JumpCovariance:
    """Covariances of the time-scale filter around one jump of length J (see jump_covariance)."""

    J: float
    period: float
    transition: str
    P_steady: Matrix            # predicted covariance on the nominal stream
    P_steady_corrected: Matrix  # corrected covariance on the nominal stream
    P_peak: Matrix              # predicted covariance at t* + J, before its measurement
    P_after: Matrix             # corrected covariance at t* + J
    recovery_steps: int             # nominal steps after t* + J until the peak is back
    regressive: bool                # I + J A invertible (always True for 'exact')


def _correct(P: Matrix, C: Matrix, Rd: Matrix) -> Matrix:
    """Measurement update of the covariance with R_d (kalman.update, Joseph form)."""
    n, p = P.shape[0], C.shape[0]
    return kalman.update(np.zeros(n), P, np.zeros(p), C, Rd, np.zeros(p))[1]


def _predict(P: Matrix, F: Matrix, Qd: Matrix) -> Matrix:
    """P(sigma) = F P(t|t) F^T + Q_d (kalman.predict)."""
    n = P.shape[0]
    return kalman.predict(np.zeros(n), P, F, Qd, np.zeros(n))[1]


def _transition(kf: TimeScaleKalmanFilter, mu: float) -> tuple[Matrix, Matrix]:
    """(F, Q_d) of kf.transition_matrices(mu), without the unused B_d (an expm less)."""
    if kf.transition == 'euler':
        return np.eye(kf.n) + mu * kf.A, mu * kf.GQGt
    return van_loan(kf.A, kf.GQGt, mu)


def steady_covariance(model: LinearModel, period: float, *, transition: str = 'euler',
                      tol: float = 1e-13, max_steps: int = 100_000) -> Matrix:
    """
    Predicted covariance of the time-scale filter on period * Z in its steady state.

    The fixed point of P -> F (P - P C^T (C P C^T + R/h)^-1 C P) F^T + Q_d with
    (F, Q_d) the filter's transition over h = period: the stabilising solution of
    the discrete algebraic Riccati equation of B&W Table 3 at constant mu = h.
    """
    kf = model.make_filter(transition, allow_nonregressive=True)
    F, Qd = _transition(kf, period)
    C, Rd = kf.C, kf.R / period
    try:
        import scipy.linalg    # noqa: I900 - on first use: 0.4 s a node may not need
        P = scipy.linalg.solve_discrete_are(F.T, C.T, Qd, Rd)
        P = (P + P.T) / 2
        resid = _predict(_correct(P, C, Rd), F, Qd) - P
        if np.all(np.isfinite(P)) and np.max(np.abs(resid)) <= 1e-8 * max(1.0, np.max(P)):
            return P
    except (np.linalg.LinAlgError, ValueError):
        pass
    # solve_discrete_are needs a regular symplectic pencil; iterate the map otherwise
    P = kf.P.copy()
    for _ in range(max_steps):
        P_new = _predict(_correct(P, C, Rd), F, Qd)
        if np.max(np.abs(P_new - P)) <= tol * max(1.0, np.max(np.abs(P_new))):
            return P_new
        P = P_new
    raise IrregularError(f'the Riccati iteration at period {period} did not converge')


def jump_covariance(model: LinearModel, J: float, *, period: float = 1.0,
                    transition: str = 'euler', recovery: float = 0.1,
                    every: Optional[int] = None,
                    P_steady: Optional[Matrix] = None) -> JumpCovariance:
    """
    How bad is the point after a gap of J: the time-scale filter around one jump.

    Setting (defined here, not in the papers): points every `period` h, so mu = h
    and the filter (B&W Table 3; F, Q_d from `transition`, R_d = R / mu) is in its
    steady state P_steady; at one point t* the next point is t* + J (mu(t*) = J), then
    the points are every h again.  Then

        P_c(t*)    = correction of P_steady with R_d = R / J   (Table 3 weighs the
                     measurement before a jump by its graininess)
        P_peak     = F_J P_c(t*) F_J^T + Q_d(J)                 the predicted covariance
                     at t* + J, the peak (Fang & de Callafon's P_{t_l})
        P_after    = correction of P_peak with R / h            the estimate at t* + J

    recovery_steps counts the nominal steps after t* + J until trace(P_pred) is within
    (1 + recovery) trace(P_steady).  J = h gives P_peak = P_steady.  With every = N the
    jump recurs after every N nominal steps, and the P's are those of the periodic
    steady state (the fixed point of the period map) instead.  P_steady, if given, is
    `steady_covariance(model, period, transition=transition)` computed once.
    """
    J, period = float(J), float(period)
    if not (J > 0 and period > 0):
        raise IrregularError(f'J and period must be > 0, got J = {J}, period = {period}')
    kf = model.make_filter(transition, allow_nonregressive=True)
    C, R = kf.C, kf.R
    F_h, Q_h = _transition(kf, period)
    F_J, Q_J = _transition(kf, J)
    regressive = transition == 'exact' or np.linalg.cond(np.eye(kf.n) + J * kf.A) < 1e12
    P_ss = (steady_covariance(model, period, transition=transition) if P_steady is None
            else np.asarray(P_steady, dtype=float))

    def over_jump(P: Matrix) -> Matrix:
        return _predict(_correct(P, C, R / J), F_J, Q_J)

    def nominal(P: Matrix) -> Matrix:
        return _predict(_correct(P, C, R / period), F_h, Q_h)

    P_before = P_ss
    if every is not None:
        every = interval(every)
        P = P_ss
        for _ in range(100_000):
            P_new = over_jump(P)
            for _ in range(every):
                P_new = nominal(P_new)
            if np.max(np.abs(P_new - P)) <= 1e-13 * max(1.0, np.max(np.abs(P_new))):
                break
            P = P_new
        else:
            raise IrregularError('the periodic Riccati iteration did not converge')
        P_before = P_new
    P_peak = over_jump(P_before)
    P = P_peak
    steps, target = 0, (1 + recovery) * np.trace(P_ss)
    while np.trace(P) > target and steps < 100_000:
        P = nominal(P)
        steps += 1
    return JumpCovariance(J, period, transition, P_before, _correct(P_before, C, R / period),
                          P_peak, _correct(P_peak, C, R / period), steps, bool(regressive))
