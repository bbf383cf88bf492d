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

Points and weights of a standard normal in [x1, d_c, d_e]; the filter maps them through the
Cholesky factor of its covariance (`ConicalScanEKF.linearise`).
"""

import math

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
