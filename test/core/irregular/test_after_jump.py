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

"""The time-scale filter around one jump (not in the papers): the filter itself, closed forms."""

import numpy as np
import pytest
import scipy.linalg

from tskf_ros.core import irregular as ir
from tskf_ros.core import linear_models as models
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.experiments import jump_covariance as jc_experiment


def test_jump_covariance_matches_the_time_scale_filter_itself():
    for model, transition, J in ((models.owc(), 'euler', 3.0), (models.owc(), 'exact', 2.0),
                                 (models.spring_mass(), 'exact', 4.0),
                                 (models.spring_mass(), 'euler', 2.5)):
        r = ir.jump_covariance(model, J, transition=transition)
        kf = TimeScaleKalmanFilter(model.A, model.C, Q=model.Q, R=model.R, G=model.G,
                                   D=model.D, x0=model.x0, P0=r.P_steady,
                                   transition=transition, allow_nonregressive=True)
        y = model.C @ model.x0 + (0 if model.D is None else model.D)
        for _ in range(3):
            kf.step(1.0, y)
        np.testing.assert_allclose(kf.P, r.P_steady, rtol=1e-9)
        kf.step(J, y)
        np.testing.assert_allclose(kf.P, r.P_peak, rtol=1e-9)
        kf.step(1.0, y)
        np.testing.assert_allclose(kf.P_corrected, r.P_after, rtol=1e-9)


def test_jump_covariance_owc_numbers():
    m = models.owc()
    c2, R = models.OWC_SLOPE ** 2, 100.0
    # Euler, h = 1: F = 2, Q_d = 1; P_ss solves P = 4 P (R/h) / (c^2 P + R/h) + 1
    P_ss = ir.steady_covariance(m, 1.0)[0, 0]
    assert P_ss == pytest.approx(4 * P_ss * R / (c2 * P_ss + R) + 1, rel=1e-12)
    for J in (1.0, 2.0, 6.0):
        r = ir.jump_covariance(m, J)
        # P_peak = (1 + J)^2 P_c + J with P_c corrected by R / J
        P_c = P_ss * (R / J) / (c2 * P_ss + R / J)
        assert r.P_peak[0, 0] == pytest.approx((1 + J) ** 2 * P_c + J, rel=1e-12)
    assert ir.jump_covariance(m, 1.0).P_peak[0, 0] == pytest.approx(P_ss, rel=1e-12)
    table = jc_experiment.table(m)
    peaks = [row['peak_variances'][0] for row in table['exact']]
    assert np.all(np.diff(peaks) > 0) and peaks[-1] == pytest.approx(81383.57, rel=1e-5)
    # a jump that recurs every 5 points: the periodic peak is at least the single one
    once = ir.jump_covariance(m, 4.0, transition='exact')
    periodic = ir.jump_covariance(m, 4.0, transition='exact', every=5)
    assert periodic.P_peak[0, 0] >= once.P_peak[0, 0] * (1 - 1e-12)


def scalar_dare(F, Qd, c2, Rd):
    """Predicted steady variance of a scalar KF: P = F^2 P Rd / (c^2 P + Rd) + Qd (closed form)."""
    # c^2 P^2 + (Rd (1 - F^2) - Qd c^2) P - Qd Rd = 0, positive root
    b = Rd * (1 - F * F) - Qd * c2
    return (-b + np.sqrt(b * b + 4 * c2 * Qd * Rd)) / (2 * c2)


def test_jump_covariance_readme_numbers_owc():
    # README: peak variance of theta 1.001 ... 6.002 rad^2 (I + mu A) and 3.2, 26.8, 201,
    # 1490, 11014, 81384 (exact) for J = 1..6; corrected 2.46e-4 whatever J
    m = models.owc()
    c2, R = models.OWC_SLOPE ** 2, 100.0
    euler = [1.001, 2.001, 3.001, 4.002, 5.002, 6.002]
    exact = [(3.2, 0.05), (26.8, 0.05), (201, 0.5), (1490, 0.5), (11014, 0.5), (81384, 0.5)]
    # exact sampled plant x' = x + w: F = e^h, Q_d = (e^{2h} - 1) / 2 (closed form)
    P_ss_exact = scalar_dare(np.e, (np.e ** 2 - 1) / 2, c2, R)
    for J, want_euler, (want_exact, tol) in zip(range(1, 7), euler, exact):
        r_eu = ir.jump_covariance(m, float(J))
        r_ex = ir.jump_covariance(m, float(J), transition='exact')
        assert r_eu.P_peak[0, 0] == pytest.approx(want_euler, abs=5e-4)
        assert r_ex.P_peak[0, 0] == pytest.approx(want_exact, abs=tol)
        P_c = P_ss_exact * (R / J) / (c2 * P_ss_exact + R / J)
        assert r_ex.P_peak[0, 0] == pytest.approx(
            np.exp(2 * J) * P_c + (np.exp(2 * J) - 1) / 2, rel=1e-9)
        for r in (r_eu, r_ex):
            assert r.P_after[0, 0] == pytest.approx(2.46e-4, abs=5e-7)
            # one measurement with R / h = 100 on the peak: P_peak R / (c^2 P_peak + R).
            # The update subtracts from P_peak (up to 8e4) a term of its size to leave
            # P_after (2.5e-4): its rounding error is about eps P_peak, eps P_peak / P_after
            # relative (7e-8 at J = 6), whatever the BLAS; the tolerance is 16 times that
            cancellation = np.finfo(float).eps * r.P_peak[0, 0] / r.P_after[0, 0]
            assert r.P_after[0, 0] == pytest.approx(
                r.P_peak[0, 0] * R / (c2 * r.P_peak[0, 0] + R),
                rel=max(1e-12, 16 * cancellation))


def test_jump_covariance_readme_numbers_spring_mass():
    # README: position variance 4.5, 10.6, 19, 29.6, 42.3 for J = 2..6 with I + mu A; with
    # the exact transition it stays near 0.25.  Reference: scipy's DARE at h = 1, then the
    # correction with R / J and the prediction over J written here.
    m = models.spring_mass()
    A, C, GQG, R = m.A, m.C, m.G @ m.Q @ m.G.T, m.R
    P_ss = scipy.linalg.solve_discrete_are((np.eye(2) + A).T, C.T, GQG, R)
    for J, want in zip(range(2, 7), [4.5, 10.6, 19.0, 29.6, 42.3]):
        r = ir.jump_covariance(m, float(J))
        assert r.P_peak[0, 0] == pytest.approx(want, abs=0.05)
        Rd = R / J
        L = P_ss @ C.T @ np.linalg.inv(C @ P_ss @ C.T + Rd)
        P_c = P_ss - L @ C @ P_ss
        F = np.eye(2) + J * A
        np.testing.assert_allclose(r.P_peak, F @ P_c @ F.T + J * GQG, rtol=1e-8, atol=1e-10)
        ex = ir.jump_covariance(m, float(J), transition='exact')
        assert 0.24 <= ex.P_peak[0, 0] <= 0.25


def test_jump_covariance_flags_the_nonregressive_spring_mass_step():
    m = models.spring_mass()
    assert not ir.jump_covariance(m, 1.0).regressive    # I + A is singular (Cai's mu = 1)
    assert ir.jump_covariance(m, 2.0).regressive
    r6 = ir.jump_covariance(m, 6.0)
    np.testing.assert_allclose(np.diag(r6.P_peak), [42.25, 133.25], rtol=1e-9)
