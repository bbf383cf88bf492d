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

"""The LQG aligner (tskf_ros.led.lqg_alignment): its EKF, its control law, and closed loop."""

import dataclasses

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.core import TimeScaleLQR

RESPONSE = led.IncidenceResponse()
SINGLE = led.LQGConfig(acquisition=(), x2_starts=())      # one EKF, the small scan only


def test_triangle_scan_of_amplitude_10_is_the_papers():
    assert led.triangle_scan(10.0) == tuple(led.SCAN_ANGLES)
    assert led.triangle_scan(4.0) == (-2.0, -4.0, -2.0, 0.0, 2.0, 4.0, 2.0, 0.0)
    with pytest.raises(led.AlignmentError, match='multiple of the step'):
        led.triangle_scan(5.0)


def test_one_step_is_the_ekf_written_out():
    """Predict with F = [[1, 0, 0], [0, 1, mu], [0, 0, 1]], update with z = x1 g(x2 + psi)."""
    cfg = SINGLE
    al = led.LQGAligner(cfg, RESPONSE)
    x, P = np.array(cfg.x0, dtype=float), np.diag(cfg.P0).astype(float)
    Q, R = np.diag(cfg.Q), cfg.R
    rng = np.random.default_rng(4)
    t, turn = 0.0, 0.0
    for k in range(30):
        mu = 1.0 if k != 12 else 3.0           # a gap: mu = 3
        if k:
            t += mu * cfg.dt
            Fm = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, mu], [0.0, 0.0, 1.0]])
            x = Fm @ x + np.array([0.0, turn, 0.0])
            P = Fm @ P @ Fm.T + mu * Q
        psi = al.scan_offset
        z = 2.5 * RESPONSE.g(3.0 + psi) + 0.2 * rng.standard_normal()
        a = x[1] + psi
        H = np.array([RESPONSE.g(a), x[0] * RESPONSE.dg(a), 0.0])
        S = H @ P @ H + R
        K = P @ H / S
        x = x + K * (z - x[0] * RESPONSE.g(a))
        P = (np.eye(3) - np.outer(K, H)) @ P
        cmd = al.step(t, z)[0]
        np.testing.assert_allclose(al.x[0], x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(al.P[0], P, rtol=1e-8, atol=1e-12)
        # the turn: mu (-L(mu) x2hat - bhat) with the stationary gain (8) at mu
        L = TimeScaleLQR(0.0, 1.0, cfg.state_weight, cfg.input_weight).stationary(mu).L[0, 0]
        turn = mu * (-L * x[1] - x[2])
        dpsi = al.scan_offset - psi
        if abs(turn + dpsi) >= cfg.min_motion:
            assert cmd == pytest.approx(turn + dpsi, rel=1e-9, abs=1e-12)
        else:
            assert abs(cmd) == pytest.approx(cfg.min_motion)
            turn = cmd - dpsi


def test_the_bank_weights_are_the_innovation_likelihoods():
    cfg = dataclasses.replace(led.LQGConfig(), x2_starts=(-8.0, 0.0, 8.0))
    al = led.LQGAligner(cfg, RESPONSE)
    z = 2.0
    x = al._x[0].copy()
    P = al._P[0].copy()
    psi = al.scan_offset
    al.step(0.0, z)
    ll = []
    for j in range(3):
        a = x[j, 1] + psi
        H = np.array([RESPONSE.g(a), x[j, 0] * RESPONSE.dg(a), 0.0])
        S = H @ P[j] @ H + cfg.R
        e = z - x[j, 0] * RESPONSE.g(a)
        ll.append(-0.5 * (e * e / S + np.log(S)))
    np.testing.assert_allclose(al.log_weight[0], np.array(ll) - max(ll), rtol=1e-12)
    assert al.members == 3
    # at the end of the acquisition each run keeps one member, its most likely
    for k in range(1, len(cfg.acquisition)):
        al.step(k * cfg.dt, z)
    assert al.members == 1 and al._x.shape == (1, 1, 3)


def test_missing_measurements_only_predict_and_vectorised_equals_one_run():
    rng = np.random.default_rng(5)
    z = 2.0 + 0.3 * rng.standard_normal((60, 3))
    z[[5, 6, 30], 1] = np.nan
    many = led.LQGAligner(runs=3)
    ones = [led.LQGAligner() for _ in range(3)]
    for k in range(60):
        cmd = many.step(k * 0.05, z[k])
        for r in range(3):
            one = ones[r].step(k * 0.05, float(z[k, r]))
            assert cmd[r] == pytest.approx(one[0], rel=1e-12, abs=1e-12)
        if k == 5:
            np.testing.assert_array_equal(many.x[1], many.x_prior[1])


def test_command_never_repeats_an_angle():
    al = led.LQGAligner(runs=50)
    rng = np.random.default_rng(6)
    for k in range(120):
        cmd = al.step(k * 0.05, 2.0 + rng.standard_normal(50))
        assert np.all(np.abs(cmd) >= al.config.min_motion - 1e-12)


def test_drift_is_estimated_and_fed_forward():
    link = led.TrackingLinkConfig(beta=14.0, noise=0.2)
    al = led.LQGAligner(runs=100)
    traj = led.simulate_tracking(al, link, np.random.default_rng(1))
    angular, measure = led.tracking(traj)
    # the goal: >= 90% at beta = 14 deg/s, noise 0.2 V (the P controller: about 30%)
    assert angular.mean() >= 90.0 and measure.mean() >= 90.0
    np.testing.assert_allclose(np.median(al.x[:, 2]), 14.0 * 0.05, rtol=0.05)


def test_make_aligner_and_bad_controller():
    assert isinstance(led.make_aligner('ekf', controller='lqg'), led.LQGAligner)
    assert isinstance(led.make_aligner('ekf'), led.ScanningEKF)
    with pytest.raises(led.AlignmentError, match="unknown controller 'pid'"):
        led.make_aligner('ekf', controller='pid')
    with pytest.raises(led.AlignmentError, match='P0 must be > 0'):
        led.LQGAligner(dataclasses.replace(led.LQGConfig(), P0=(1.0, 0.0, 0.1)))
    with pytest.raises(led.AlignmentError, match='state_weight must be > 0'):
        led.LQGAligner(dataclasses.replace(led.LQGConfig(), state_weight=-1.0))
