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

"""The scanning EKF of Solanki et al. 2018 (Section IV): Jacobian (17) and the EKF."""

import numpy as np
import pytest
from solanki_paper import dg_paper, g_paper

from tskf_ros import led


def h_paper(x, psi, shift, psi_prev, s):
    """Eq. (16) written here: [x1 g(x2 + psi_k), x1 g(x2 - shift + psi_{k-1})] in degrees."""
    return np.stack([x[:, 0] * g_paper(s * (x[:, 1] + psi)),
                     x[:, 0] * g_paper(s * (x[:, 1] - shift + psi_prev))], axis=-1)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(4)
    ekf = led.ScanningEKF(runs=50)
    s = ekf.response.units_per_degree
    x = np.column_stack([rng.uniform(0.5, 4.0, 50), rng.uniform(-20.0, 20.0, 50)])
    shift = rng.uniform(-5.0, 5.0, 50)
    psi_prev = rng.choice(led.SCAN_ANGLES, 50)
    psi = 6.0
    C = ekf.jacobian(x, psi, shift, psi_prev)
    np.testing.assert_allclose(ekf.h(x, psi, shift, psi_prev),
                               h_paper(x, psi, shift, psi_prev, s), rtol=1e-12)
    eps = 1e-6
    for j in range(2):
        dx = np.zeros(2)
        dx[j] = eps
        numeric = (h_paper(x + dx, psi, shift, psi_prev, s)
                   - h_paper(x - dx, psi, shift, psi_prev, s)) / (2 * eps)
        np.testing.assert_allclose(C[:, :, j], numeric, rtol=1e-5, atol=1e-8)


class ReferenceEKF:
    """
    One run of the scanning EKF, eq. (13)-(21), written here from the paper (Table I).

    Predict x2 += u_{k-1}, P += mu Q; update with the pair (12) [z_k, z_prev] (the first
    measurement alone), K = P C^T S^-1, P = (I - K C) P; u_k = -G x2; command
    u_k + psi_{k+1} - psi_k.  A missing z only predicts.
    """

    def __init__(self, s):
        self.s = s
        self.x, self.P = np.array([2.0, 0.0]), np.diag([100.0, 1000.0])
        self.Q, self.R, self.G = np.diag([0.25, 1.0]), np.eye(2), 0.5
        self.scan = [-2.0, -4.0, -6.0, -8.0, -10.0, -8.0, -6.0, -4.0, -2.0, 0.0,
                     2.0, 4.0, 6.0, 8.0, 10.0, 8.0, 6.0, 4.0, 2.0, 0.0]
        self.k, self.t, self.u, self.since = 0, None, 0.0, 0.0
        self.z_prev = self.psi_prev = None
        self.det = None

    def row(self, angle):
        return np.array([g_paper(self.s * angle), self.x[0] * self.s * dg_paper(self.s * angle)])

    def step(self, t, z):
        if self.t is not None:
            mu = (t - self.t) / 0.05
            self.x[1] += self.u
            self.P = self.P + mu * self.Q
        self.t = t
        psi = self.scan[self.k % 20]
        if z is not None:
            x1, x2 = self.x
            rows = [self.row(x2 + psi)]
            res = [z - x1 * g_paper(self.s * (x2 + psi))]
            if self.z_prev is not None:
                a2 = x2 - self.since + self.psi_prev
                rows.append(self.row(a2))
                res.append(self.z_prev - x1 * g_paper(self.s * a2))
            C = np.array(rows)
            R = self.R[:len(rows), :len(rows)]
            K = self.P @ C.T @ np.linalg.inv(C @ self.P @ C.T + R)
            self.x = self.x + K @ np.array(res)
            self.P = (np.eye(2) - K @ C) @ self.P
            self.det = np.linalg.det(C) if len(rows) == 2 else None
            self.z_prev, self.psi_prev, self.since = z, psi, 0.0
        self.u = -self.G * self.x[1]
        self.since += self.u
        self.k += 1
        return self.u + self.scan[self.k % 20] - psi


def test_ekf_equals_the_paper_written_out():
    rng = np.random.default_rng(8)
    ekf = led.ScanningEKF()
    ref = ReferenceEKF(ekf.response.units_per_degree)
    t, phi = 10.0, 4.0
    for k in range(60):
        t += 0.05 * (3 if k in (20, 41) else 1)          # two gaps: mu = 3
        clean = 2.0 * g_paper(17.697 * phi)
        z = None if k in (7, 30, 31) else float(clean + 0.2 * rng.standard_normal())
        cmd = ekf.step(t, z)
        want = ref.step(t, z)
        assert cmd[0] == pytest.approx(want, rel=1e-7, abs=1e-9), k
        np.testing.assert_allclose(ekf.x[0], ref.x, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(ekf.P[0], ref.P, rtol=1e-6, atol=1e-8 * np.abs(ref.P).max())
        if z is not None and ref.det is not None:
            assert ekf.det[0] == pytest.approx(ref.det, rel=1e-7, abs=1e-12)
        phi += 0.06 + want + 0.1 * rng.standard_normal()


def test_paper_gain_runs_with_nonzero_det_away_from_two_degrees():
    ekf = led.ScanningEKF(led.EKFConfig(gain=0.5), runs=3)
    refs = [ReferenceEKF(ekf.response.units_per_degree) for _ in range(3)]
    for t, z in ((0.0, [2.0, 2.5, 3.0]), (0.05, [2.2, 2.4, 2.9])):
        ekf.step(t, z)
        for ref, zi in zip(refs, z):
            ref.step(t, zi)
    # det C_k of (17) at the second step, from the paper's rows written out
    np.testing.assert_allclose(ekf.det, [ref.det for ref in refs], rtol=1e-7)
    assert np.all(np.abs(ekf.det) > 1e-3) and not ekf.singular.any()


def test_step_interface_for_a_node():
    ekf = led.ScanningEKF()
    first = ekf.step(10.0, 2.5)
    # the first measurement alone (no pair): x1 = 2, x2 = 0 at psi_0 = -2 deg
    s = ekf.response.units_per_degree
    c = np.array([g_paper(-2.0 * s), 2.0 * s * dg_paper(-2.0 * s)])
    P0 = np.diag([100.0, 1000.0])
    K = P0 @ c / (c @ P0 @ c + 1.0)
    x = np.array([2.0, 0.0]) + K * (2.5 - 2.0 * g_paper(-2.0 * s))
    # command u_0 + psi_1 - psi_0 = -0.5 x2 + (-4) - (-2)
    assert first.shape == (1,)
    assert first[0] == pytest.approx(-0.5 * x[1] - 2.0, rel=1e-9)
    np.testing.assert_allclose(ekf.x[0], x, rtol=1e-9)
    ekf.step(10.05, None)
    ekf.step(10.10, float('nan'))
    with pytest.raises(led.AlignmentError, match='stale stamp'):
        ekf.step(10.10, 2.0)


def test_gap_prediction_uses_the_stamps():
    a, b = led.ScanningEKF(), led.ScanningEKF()
    for ekf in (a, b):
        ekf.step(0.0, 2.0)
        ekf.step(0.05, 2.6)
    P_post = a.P.copy()
    applied = [a.u[0]]
    for k in (2, 3, 4):          # a: one call per missing sample
        a.step(0.05 * k, None)
        applied.append(a.u[0])
    b.step(0.20, None)           # b: a single call after the gap, mu = 3
    np.testing.assert_allclose(a.P_prior, P_post + 3.0 * a.Q)
    np.testing.assert_allclose(b.P_prior, P_post + 3.0 * b.Q)
    # the next measurement is paired with the last one, shifted by the control since
    assert a.since[0] == pytest.approx(sum(applied))
    assert not a.updated.any()


@pytest.mark.parametrize('make', [led.ScanningEKF, led.LQGAligner])
def test_a_gap_beyond_max_mu_is_refused_whole(make):
    """A gap over MAX_MU steps: AlignmentError, the clock and filter as they were; then on."""
    from tskf_ros.led.scanning_ekf import MAX_MU
    ekf = make()
    ekf.step(0.0, 2.0)
    ekf.step(0.05, 2.6)
    x, P = ekf.x.copy(), ekf.P.copy()
    with pytest.raises(led.AlignmentError, match='nominal steps, beyond'):
        ekf.step(0.05 + 1.01 * MAX_MU * 0.05, 2.0)
    assert ekf.clock.stamp == 0.05
    np.testing.assert_array_equal(ekf.x, x)
    np.testing.assert_array_equal(ekf.P, P)
    ekf.step(0.10, 2.0)
    assert np.all(np.isfinite(ekf.x)) and np.all(np.isfinite(ekf.P))
