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
The sigma-point rules of N(0, I_3) for the conical-scan EKF's regression (`conical_ekf`).

Points and weights of a standard normal in [x1, d_c, d_e], and the statistical linear
regression of the scanned sample h = x1 g_r(|d + s|) over them (`regression`), mapped
through the Cholesky factor of the filter's covariance (`ConicalScanEKF.linearise`).
"""

import math
from typing import Callable

import numpy as np

from tskf_ros.led.intensity_model import FloatArray


def _sigma_points() -> dict[str, tuple[FloatArray, FloatArray]]:
    """
    Return the unit points and weights of N(0, I_3) of each sigma-point rule.

    'cubature': the third-degree spherical-radial rule, +-sqrt(3) e_i, weights 1/6
    (Arasaratnam & Haykin, IEEE TAC 2009); exact for polynomials of degree 3, so not
    for the variance of h's quadratic terms.  'gauss_hermite': the tensor product of the
    3-point Gauss-Hermite rule, nodes 0, +-sqrt(3) with weights 2/3, 1/6 (Ito & Xiong,
    IEEE TAC 2000): 27 points, exact for degree 5 per coordinate, so for that variance.
    'gauss_hermite_5': the 5-point rule's product (the same paper), nodes the roots of
    He_5, 0 and +-sqrt(5 -+ sqrt(10)), weights 5!/(5 He_4(x_i))^2 = 8/15 and
    (7 +- 2 sqrt(10))/60: 125 points, exact for degree 9 per coordinate (CONSISTENT's).
    """
    cubature = math.sqrt(3.0) * np.vstack([np.eye(3), -np.eye(3)])
    rules = {'cubature': (cubature, np.full(6, 1.0 / 6.0))}
    root10 = math.sqrt(10.0)
    for name, node, weight in (
            ('gauss_hermite', np.array([-math.sqrt(3.0), 0.0, math.sqrt(3.0)]),
             np.array([1, 4, 1]) / 6.0),
            ('gauss_hermite_5',
             np.array([-math.sqrt(5.0 + root10), -math.sqrt(5.0 - root10), 0.0,
                       math.sqrt(5.0 - root10), math.sqrt(5.0 + root10)]),
             np.array([7.0 - 2.0 * root10, 7.0 + 2.0 * root10, 32.0,
                       7.0 + 2.0 * root10, 7.0 - 2.0 * root10]) / 60.0)):
        grid = np.stack(np.meshgrid(node, node, node, indexing='ij'), axis=-1).reshape(-1, 3)
        rules[name] = (grid, np.einsum('i,j,k->ijk', weight, weight, weight).reshape(-1))
    return rules


SIGMA_POINTS = _sigma_points()


def regression(rule: str, g: Callable[[FloatArray], FloatArray], x: FloatArray, P: FloatArray,
               offset: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """
    Return (H, hx, R_h) of h = x1 g(|d + s|) regressed over N(x, P) on a rule's points.

    The statistical linear regression (Lefebvre, Bruyninckx & De Schutter, IEEE TAC
    2002; Sarkka, Bayesian Filtering and Smoothing, 2013, Sec. 5.6) on the points
    x + L xi_p of [x1, d] (L L^T = P[:3, :3]; h does not depend on b), xi_p and w_p the
    rule's (SIGMA_POINTS): hx = sum w_p h_p, P_xz = sum w_p L xi_p (h_p - hx),
    H = P_xz^T P^-1 and R_h = sum w_p (h_p - hx)^2 - H P_xz >= 0, what the line leaves
    out.  x (n, 5), P (n, 5, 5), offset s (2,) or (n, 2); H (n, 1, 5), hx and R_h (n,).
    """
    nodes, weights = SIGMA_POINTS[rule]
    L = np.linalg.cholesky(P[:, :3, :3])
    spread = nodes @ L.transpose(0, 2, 1)                    # L xi_p, (n, p, 3)
    X = x[:, None, :3] + spread
    e = X[:, :, 1:3] + np.reshape(offset, (-1, 1, 2))
    Z = X[:, :, 0] * g(np.hypot(e[..., 0], e[..., 1]))
    hx = Z @ weights
    Pxz = (((Z - hx[:, None]) * weights)[:, None, :] @ spread)[:, 0, :]
    H3 = np.linalg.solve(P[:, :3, :3], Pxz[:, :, None])[:, :, 0]
    H = np.zeros((x.shape[0], 1, 5))
    H[:, 0, :3] = H3
    R_h = np.maximum(((Z - hx[:, None]) ** 2) @ weights - np.einsum('ri,ri->r', H3, Pxz), 0.0)
    return H, hx, R_h
