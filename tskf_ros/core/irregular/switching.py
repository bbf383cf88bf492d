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
The switching and lifted Kalman filters of Fang & de Callafon 2011 for irregular sampling.

System (1)-(2) on the grid k = 0, 1, ... of period T_s: x_{k+1} = A x_k + B u_k + w_k,
y_{t_l} = C x_{t_l} + v_{t_l}, measured only at the sampling instants t_0 < t_1 < ...
The switching filter is eqs. (13)-(17) (gamma_k = 0 between samples); the lifted filter,
eqs. (3)-(8), steps from one sampling instant to the next.  Both use the predict and update
of tskf_ros.core.kalman.
"""

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core import kalman
from tskf_ros.core.irregular.common import interval, IrregularError
from tskf_ros.core.matrices import as_matrix, check_covariance


def _check_model(A: ArrayLike, C: ArrayLike, Q: ArrayLike, R: ArrayLike,
                 B: Optional[ArrayLike] = None) -> tuple[NDArray[np.float64], ...]:
    """Return (A, C, Q, R, B) as checked float matrices (B: n x 1 zeros if None)."""
    A = as_matrix(A, 'A')
    n = A.shape[0]
    if A.shape != (n, n):
        raise IrregularError(f'A must be square, got shape {A.shape}')
    C = as_matrix(C, 'C')
    if C.shape[1] != n:
        raise IrregularError(f'C must have {n} columns, got shape {C.shape}')
    Q = check_covariance(as_matrix(Q, 'Q', (n, n)), 'Q')
    m = C.shape[0]
    R = check_covariance(as_matrix(R, 'R', (m, m)), 'R', definite=True)
    B = np.zeros((n, 1)) if B is None else as_matrix(B, 'B', column=True)
    if B.shape[0] != n:
        raise IrregularError(f'B must have {n} rows, got shape {B.shape}')
    return A, C, Q, R, B


@dataclass
class FilterHistory:
    """Priors and posteriors of a run: at every step (switching) or every sample (lifted)."""

    k: NDArray[np.int64]        # time indices of the rows
    x_prior: NDArray[np.float64]    # (N, n): xhat_k^-
    P_prior: NDArray[np.float64]    # (N, n, n): P_k^- (at a sampling instant: the peak)
    x_post: NDArray[np.float64]     # (N, n): xhat_k^+
    P_post: NDArray[np.float64]     # (N, n, n): P_k^+


class SwitchingKalmanFilter:
    """
    The binary switching Kalman filter, Fang & de Callafon eqs. (13)-(17).

    `x`, `P` hold the current estimate; `predict(u)` moves it one step of T_s and
    `update(y)` corrects it, with `y=None` the explicit gamma_k = 0 branch.
    """

    def __init__(self, A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike,
                 x0: ArrayLike, P0: ArrayLike, B: Optional[ArrayLike] = None) -> None:
        self.A, self.C, self.Q, self.R, self.B = _check_model(A, C, Q, R, B)
        n = self.A.shape[0]
        self.x = np.array(x0, dtype=float).reshape(n)
        self.P = check_covariance(as_matrix(P0, 'P0', (n, n)), 'P0')
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        self.K: Optional[NDArray[np.float64]] = None

    def predict(self, u: Optional[ArrayLike] = None) -> None:
        """Time update from k-1 to k, eqs. (13)-(14) (= (9)-(10) between samples)."""
        u_ = np.zeros(self.B.shape[1]) if u is None else np.asarray(u, float).reshape(-1)
        # (13) xhat_k^- = A xhat_{k-1}^+ + B u_{k-1};  (14) P_k^- = A P_{k-1}^+ A^T + Q
        self.x, self.P = kalman.predict(self.x, self.P, self.A, self.Q, self.B @ u_)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def update(self, y: Optional[ArrayLike]) -> None:
        """Measurement update at k, eqs. (15)-(17); y=None is gamma_k = 0, (11)-(12)."""
        if y is None:
            # (11)-(12) xhat_k^+ = xhat_k^-, P_k^+ = P_k^-
            self.K = None
            self.x_post, self.P_post = self.x.copy(), self.P.copy()
            return
        z = np.asarray(y, float).reshape(-1)
        # (15) K_k = P_k^- C^T (C P_k^- C^T + R)^-1, (16) xhat_k^+ = xhat_k^- + K_k (y_k -
        # C xhat_k^-), (17) P_k^+ = (I - K_k C) P_k^-, in Joseph form (equal in exact
        # arithmetic, symmetric positive semi-definite in floating point)
        self.x, self.P, _, _, self.K = kalman.update(self.x, self.P, z, self.C, self.R,
                                                     np.zeros(z.size))
        self.x_post, self.P_post = self.x.copy(), self.P.copy()


def _rows(values: Optional[ArrayLike], count: int, width: int, name: str
          ) -> NDArray[np.float64]:
    """Return values as a (count, width) float array (None: zeros)."""
    if values is None:
        return np.zeros((count, width))
    a = np.asarray(values, dtype=float).reshape(count, -1)
    if a.shape[1] != width:
        raise IrregularError(f'{name} must have {width} columns, got {a.shape[1]}')
    return a


def run_switching(A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike, x0: ArrayLike,
                  P0: ArrayLike, y: ArrayLike, B: Optional[ArrayLike] = None,
                  u: Optional[ArrayLike] = None) -> FilterHistory:
    """
    Run eqs. (13)-(17) over k = 0..N-1; a NaN row of y (N x m) is gamma_k = 0.

    x0, P0 are the prior at k = 0 (xhat_0^-, P_0^-); u (N x p, optional) is the input,
    u_k acting from k to k + 1.
    """
    kf = SwitchingKalmanFilter(A, C, Q=Q, R=R, x0=x0, P0=P0, B=B)
    n, m, p = kf.A.shape[0], kf.C.shape[0], kf.B.shape[1]
    y = np.asarray(y, dtype=float).reshape(-1, m)
    N = y.shape[0]
    u = _rows(u, N, p, 'u')
    h = FilterHistory(np.arange(N), np.zeros((N, n)), np.zeros((N, n, n)),
                      np.zeros((N, n)), np.zeros((N, n, n)))
    for k in range(N):
        if k > 0:
            kf.predict(u[k - 1])
        h.x_prior[k], h.P_prior[k] = kf.x_prior, kf.P_prior
        gamma = not np.any(np.isnan(y[k]))
        kf.update(y[k] if gamma else None)
        h.x_post[k], h.P_post[k] = kf.x_post, kf.P_post
    return h


def lifted_matrices(A: ArrayLike, B: ArrayLike, kappa: int
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """
    (Phi, Gamma, Omega) of the lifted system, eq. (3), over an interval of kappa steps.

    Phi = A^kappa, Gamma = [A^{kappa-1} B ... A B  B], Omega = [A^{kappa-1} ... A  I]
    (the paper prints a stray B in Omega's first block).
    """
    A = as_matrix(A, 'A')
    B = as_matrix(B, 'B', column=True)
    kappa = interval(kappa)
    powers = [np.eye(A.shape[0])]
    for _ in range(kappa):
        powers.append(A @ powers[-1])
    Phi = powers[kappa]
    Gamma = np.hstack([powers[kappa - 1 - i] @ B for i in range(kappa)])
    Omega = np.hstack([powers[kappa - 1 - i] for i in range(kappa)])
    return Phi, Gamma, Omega


def run_lifted(A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike, x0: ArrayLike,
               P0: ArrayLike, times: Sequence[int], y: ArrayLike, B: Optional[ArrayLike] = None,
               u: Optional[ArrayLike] = None) -> FilterHistory:
    """
    Run the lifted filter, eqs. (4)-(8), over the sampling instants only.

    times are the sampling instants t_0 < t_1 < ... (integers, t_0 = 0 is where x0, P0
    are the prior); y (L x m) the measurements there; u (t_last x p or longer) the
    input at every step.  Rows of the result are the sampling instants.
    """
    A, C, Q, R, B = _check_model(A, C, Q, R, B)
    n, m, p = A.shape[0], C.shape[0], B.shape[1]
    t = np.asarray(times, dtype=int).reshape(-1)
    if t.size == 0 or np.any(np.diff(t) <= 0):
        raise IrregularError('times must be a non-empty strictly increasing sequence')
    y = np.asarray(y, dtype=float).reshape(t.size, m)
    if u is None:
        u = np.zeros((int(t[-1] - t[0]), p))
    u = np.asarray(u, dtype=float).reshape(-1, p)
    if u.shape[0] < t[-1] - t[0]:
        raise IrregularError(f'u needs {t[-1] - t[0]} rows (one per step), got {u.shape[0]}')
    L = t.size
    h = FilterHistory(t.copy(), np.zeros((L, n)), np.zeros((L, n, n)),
                      np.zeros((L, n)), np.zeros((L, n, n)))
    x = np.array(x0, dtype=float).reshape(n)
    P = check_covariance(as_matrix(P0, 'P0', (n, n)), 'P0')
    for ell in range(L):
        if ell > 0:
            kappa = int(t[ell] - t[ell - 1])
            Phi, Gamma, Omega = lifted_matrices(A, B, kappa)
            # u~ = [u_{t_{l-1}}^T ... u_{t_l - 1}^T]^T
            u_tilde = u[t[ell - 1] - t[0]:t[ell] - t[0]].reshape(-1)
            # Delta = diag(Q, ..., Q), kappa blocks
            Delta = np.kron(np.eye(kappa), Q)
            # (4) xhat_{t_l}^- = Phi xhat_{t_{l-1}}^+ + Gamma u~
            # (5) P_{t_l}^- = Phi P_{t_{l-1}}^+ Phi^T + Omega Delta Omega^T
            x, P = kalman.predict(x, P, Phi, Omega @ Delta @ Omega.T, Gamma @ u_tilde)
        h.x_prior[ell], h.P_prior[ell] = x, P
        # (6) K = P^- C^T (C P^- C^T + R)^-1, (7) xhat^+ = xhat^- + K (y - C xhat^-),
        # (8) P^+ = (I - K C) P^-, here in Joseph form (equal in exact arithmetic)
        x, P, _, _, _ = kalman.update(x, P, y[ell], C, R, np.zeros(m))
        h.x_post[ell], h.P_post[ell] = x, P
    return h
