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
The Kalman-Bucy filter (Bohner & Wintz 2013, Table 2): Table 3 at right-dense points.

Over a stretch where mu = 0 the estimate and its covariance follow the ODEs
  xhat' = A xhat + B u + K (y - C xhat - D),  K = P C^T R^-1,
  P' = A P + P A^T + G Q G^T - K C P,
solved together by scipy's RK45 (the tests: the covariance matches the closed-form scalar
Riccati solution to about 1e-9).  scipy is imported here only: a node never integrates.
"""

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.matrices import FilterError

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['integrate', 'KalmanBucyModel']


@dataclass(frozen=True)
class KalmanBucyModel:
    """The continuous model's matrices (G Q G^T as one matrix)."""

    A: Matrix
    B: Matrix
    C: Matrix
    D: Vector
    GQGt: Matrix
    R: Matrix


def integrate(model: KalmanBucyModel, x: Vector, P: Matrix, duration: float,
              y: Callable[[float], ArrayLike], u: Callable[[float], Vector], *,
              rtol: float = 1e-9, atol: float = 1e-12) -> tuple[Vector, Matrix]:
    """
    Return (xhat, P) after `duration` of the ODEs from (x, P).

    y(s) and u(s): the measurement and input at s in [0, duration].  Raises FilterError if
    the solver fails.
    """
    n = x.shape[0]
    A, B, C, D, GQGt = model.A, model.B, model.C, model.D, model.GQGt
    Rinv = np.linalg.inv(model.R)

    def rhs(s: float, z: Vector) -> Vector:
        xh = z[:n]
        P = z[n:].reshape(n, n)
        # K = P C^T R^-1
        K = P @ C.T @ Rinv
        ys = np.asarray(y(s), dtype=float).reshape(-1)
        # xhat' = A xhat + B u + K (y - C xhat - D)
        dx = A @ xh + B @ u(s) + K @ (ys - C @ xh - D)
        # P' = A P + P A^T + G Q G^T - K C P
        dP = A @ P + P @ A.T + GQGt - K @ C @ P
        return np.concatenate([dx, ((dP + dP.T) / 2).reshape(-1)])

    z0 = np.concatenate([x, P.reshape(-1)])
    import scipy.integrate    # noqa: I900 - here: 0.3 s that a node never needs
    sol = scipy.integrate.solve_ivp(rhs, (0.0, duration), z0, method='RK45',
                                    rtol=rtol, atol=atol)
    if not sol.success:
        raise FilterError(f'Kalman-Bucy integration failed: {sol.message}')
    zf = sol.y[:, -1]
    P_end = zf[n:].reshape(n, n)
    return zf[:n], (P_end + P_end.T) / 2
