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

"""The sigma-point rules of the conical-scan EKF against the moments of N(0, I_3)."""

import numpy as np
import pytest

from tskf_ros.led.two_axis.sigma_points import SIGMA_POINTS


def test_gauss_hermite_points_integrate_the_gaussian_moments():
    """
    The sigma-point rules against the moments of N(0, I_3) in closed form.

    Gauss-Hermite: E x_i^2 = 1, E x_i^4 = 3, E x_i^2 x_j^2 = 1, odd moments 0 (and with 5
    points E x_i^6 = 15, E x_i^8 = 105, E x_i^4 x_j^2 = 3).  The
    cubature rule gets E x_i^4 = 3 but E x_i^2 x_j^2 = 0: the variance of a product term
    such as x1 d of h, which is why it is not CONSISTENT's.
    """
    for rule, cross in (('gauss_hermite', 1.0), ('gauss_hermite_5', 1.0), ('cubature', 0.0)):
        X, w = SIGMA_POINTS[rule]
        assert w.sum() == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_allclose(w @ X, 0.0, atol=1e-15)
        np.testing.assert_allclose(np.einsum('p,pi,pj->ij', w, X, X), np.eye(3), atol=1e-14)
        np.testing.assert_allclose(w @ X ** 4, 3.0, rtol=1e-14)
        assert float(w @ (X[:, 0] ** 2 * X[:, 1] ** 2)) == pytest.approx(cross, abs=1e-14)
        np.testing.assert_allclose(w @ (X[:, 0] * X[:, 1] ** 2), 0.0, atol=1e-14)
    X, w = SIGMA_POINTS['gauss_hermite_5']     # 5 points: exact to degree 9 per axis
    np.testing.assert_allclose(w @ X ** 6, 15.0, rtol=1e-13)
    np.testing.assert_allclose(w @ X ** 8, 105.0, rtol=1e-13)
    assert float(w @ (X[:, 0] ** 4 * X[:, 1] ** 2)) == pytest.approx(3.0, rel=1e-13)
