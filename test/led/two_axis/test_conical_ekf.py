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

"""The conical-scan EKF: Jacobians, consistency (NEES, NIS), mu from the stamps, one axis."""

import math

import numpy as np
import pytest
import scipy.stats

from tskf_ros.led.intensity_model import AlignmentError, IncidenceResponse
from tskf_ros.led.scanning_ekf import StampClock
from tskf_ros.led.two_axis.conical_ekf import (ConicalEKFConfig, ConicalScanEKF, scan_loss,
                                               transition)
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig
from tskf_ros.led.two_axis.pointing_geometry import joint_turn, tangent_error
from tskf_ros.led.two_axis.radial_response import RadialResponse

NOISE_LEVELS = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)


def test_jacobian_matches_finite_differences():
    """H = dh/dx against central differences at random states and scan offsets."""
    rng = np.random.default_rng(0)
    ekf = ConicalScanEKF(runs=50)
    x = np.column_stack([rng.uniform(0.5, 4.0, 50), rng.uniform(-12, 12, (50, 2)),
                         rng.normal(0, 0.1, (50, 2))])
    for offset in ekf.scan[::5]:
        H = ekf.jacobian(x, offset)[:, 0, :]
        for i in range(5):
            h = 1e-6 * max(1.0, float(np.max(np.abs(x[:, i]))))
            up, down = x.copy(), x.copy()
            up[:, i] += h
            down[:, i] -= h
            fd = (ekf.h(up, offset) - ekf.h(down, offset)) / (2 * h)
            np.testing.assert_allclose(H[:, i], fd, rtol=1e-6, atol=1e-9)


def test_jacobian_at_the_scan_centre_is_finite():
    """|d + s| = 0 (the boresight on the source): the gradient is 0, not NaN."""
    ekf = ConicalScanEKF()
    x = np.array([[2.0, -ekf.scan[0, 0], -ekf.scan[0, 1], 0.0, 0.0]])
    H = ekf.jacobian(x, ekf.scan[0])
    assert np.all(np.isfinite(H)) and np.allclose(H[0, 0, 1:3], 0.0)


def test_transition_moves_the_error_by_mu_drifts():
    """F(mu) x: d + mu b, x1 and b unchanged (mu = 2.5)."""
    x = np.array([2.0, 1.0, -1.0, 0.1, -0.2])
    np.testing.assert_allclose(transition(2.5) @ x, [2.0, 1.25, -1.5, 0.1, -0.2])


def test_mu_comes_from_the_stamps_with_jitter():
    """The graininess mu = elapsed / dt per call, for jittered stamps; P grows by mu Q."""
    rng = np.random.default_rng(1)
    stamps = np.cumsum(0.05 + rng.uniform(-0.02, 0.02, 30))
    clock = StampClock(0.05)
    mus = [clock.tick(t) for t in stamps]
    np.testing.assert_allclose(mus[1:], np.diff(stamps) / 0.05, rtol=1e-12)
    ekf = ConicalScanEKF()
    ekf.step(0.0, None)
    P = ekf.P.copy()
    ekf.step(0.13, None)         # a missing sample 2.6 nominal steps later
    F = transition(2.6)
    np.testing.assert_allclose(ekf.P[0], F @ P[0] @ F.T + 2.6 * ekf.Q, rtol=1e-12)


def _nees_nis(noise, runs=200, steps=300, seed=0, jitter=0.0):
    """
    Run the EKF in closed loop at `noise`; return the ANEES of [x1, d_c, d_e], its band.

    The truth: x1, and the error of the mean pointing (the boresight less the scan offset)
    in the tangent plane at the source.  Runs that leave the 15 deg cone are not the
    filter's domain (its x1 and error trade off in the dark) and are left out; the first
    2 s (the convergence from P0) too.  Returns (ANEES, band, mean NIS).
    """
    plant = PanTiltLink(PanTiltLinkConfig(noise=noise, jitter=jitter), runs=runs, seed=seed)
    ekf = ConicalScanEKF(ConicalEKFConfig(noise=noise), runs=runs)
    nees, nis, theta = (np.empty((steps, runs)) for _ in range(3))
    for k in range(steps):
        s = plant.sample()
        mean = s.joints - joint_turn(ekf.scan_offset, s.joints[:, 1])
        d = tangent_error(mean[:, 0], mean[:, 1], s.source[:, 0], s.source[:, 1])
        turn = ekf.step(s.t, s.z)
        e = ekf.x[:, :3] - np.column_stack([s.x1, d])
        nees[k] = np.einsum('ri,rij,rj->r', e, np.linalg.inv(ekf.P[:, :3, :3]), e)
        nis[k], theta[k] = ekf.nis, s.theta
        plant.command_turn(turn)
    keep = theta.max(axis=0) <= 15.0
    m = int(keep.sum())
    lo, hi = scipy.stats.chi2.ppf([0.025, 0.975], 3 * m) / m
    return float(np.mean(nees[40:, keep])), (lo, hi), float(np.nanmean(nis[40:, keep]))


def test_nees_is_in_its_band_at_1_volt():
    """At 1 V, the mean over steps of the ANEES of [x1, d] (200 runs) is in its 95 % band."""
    anees, (lo, hi), _ = _nees_nis(1.0)
    assert lo < anees < hi, (anees, lo, hi)


def test_nees_with_jittered_stamps_at_1_volt():
    """Stamps jittered by up to +-20 ms: mu from the stamps keeps the ANEES in its band."""
    anees, (lo, hi), _ = _nees_nis(1.0, jitter=0.02)
    assert lo < anees < hi, (anees, lo, hi)


@pytest.mark.xfail(strict=True, reason='measured outside the band: conservative at 0 and '
                   '0.5 V (ANEES 1.35, 2.51; R has a 0.2 V model-error floor), overconfident '
                   'from 1.5 V (3.9 to 4.5 against 3.4: the EKF linearisation far off axis)')
@pytest.mark.parametrize('noise', [0.0, 0.5, 1.5, 2.0, 2.5])
def test_nees_in_band_at_the_other_noise_levels(noise):
    """The same test at the other reported noise levels (not met yet)."""
    anees, (lo, hi), _ = _nees_nis(noise)
    assert lo < anees < hi, (anees, lo, hi)


@pytest.mark.xfail(strict=True, reason='measured: the mean NIS is 0.13 at 0 V, 0.84 at '
                   '0.5 V, 0.94 to 0.98 from 1 V, below the band of some 50 000 samples '
                   '(about 1 +- 0.01)')
@pytest.mark.parametrize('noise', NOISE_LEVELS)
def test_nis_in_band(noise):
    """The mean NIS of the kept runs in the 95 % band of its chi^2 (not met yet)."""
    _, _, nis = _nees_nis(noise)
    n = 200 * 260
    lo, hi = scipy.stats.chi2.ppf([0.025, 0.975], n) / n
    assert lo < nis < hi, (nis, lo, hi)


class _SignedRadial:
    """g_r as a function of a signed angle on one axis, for the one-axis LQG filter."""

    def __init__(self, radial):
        self.radial = radial

    def g(self, phi):
        return self.radial.g(np.abs(phi))

    def dg(self, phi):
        return self.radial.slope_over_theta(np.abs(phi)) * phi


def test_reduces_to_the_one_axis_filter():
    """
    The elevation states pinned (P0 = Q = 0) and the scan on the cross-elevation axis.

    The correspondence: [x1, d_c, b_c] of the conical EKF with the LQR is the state
    [x1, x2, b] of lqg_alignment's EKF and LQR on the same (signed, one-axis) response
    g_r, the same triangle scan, R = 1 and the same stamps and samples: x, P and the
    turns agree to rounding.
    """
    from tskf_ros.led.lqg_alignment import LQGAligner, LQGConfig, triangle_scan
    radial = RadialResponse()
    scan = triangle_scan(4.0)
    lqg = LQGAligner(LQGConfig(acquisition=(), x2_starts=(), min_motion=0.0, scan=scan,
                               P0=(1.0, 4.0, 0.1)), _SignedRadial(radial), runs=3)
    ekf = ConicalScanEKF(ConicalEKFConfig(
        controller='lqr', noise=1.0, model_noise=0.0, x0=(2.0, 0.0, 0.0, 0.0, 0.0),
        P0=(1.0, 4.0, 0.0, 0.1, 0.0), Q=(0.0025, 0.01, 0.0, 1e-5, 0.0)), radial, runs=3)
    ekf.scan = np.column_stack([scan, np.zeros(len(scan))])
    rng = np.random.default_rng(5)
    t = 0.0
    for k in range(120):
        t += 0.05 * (1.0 + 0.3 * rng.uniform(-1, 1))
        z = None if k % 17 == 5 else rng.uniform(0.5, 3.0, 3)
        a = lqg.step(t, z)
        b = ekf.step(t, z)
        np.testing.assert_allclose(b[:, 0], a, atol=1e-9)
        np.testing.assert_allclose(b[:, 1], 0.0, atol=1e-12)
        i = [0, 1, 3]
        np.testing.assert_allclose(ekf.x[:, i], lqg.x, atol=1e-9)
        np.testing.assert_allclose(ekf.P[:, i][:, :, i], lqg.P, atol=1e-9)


def test_scan_loss_is_one_less_the_radial_response_at_r():
    """scan_loss(r) = 1 - g_r(r)/g_r(0), g_r the mean of g(+-r) (eq. (4)); 4 deg: 15 %."""
    g = IncidenceResponse()
    for r in (2.0, 4.0, 6.0):
        expected = 1.0 - (g.g(r) + g.g(-r)) / (2.0 * g.g(0.0))
        assert scan_loss(r) == pytest.approx(float(expected), rel=1e-9)
    assert 0.14 < scan_loss(4.0) < 0.16


def test_the_scan_costs_scan_loss_on_the_source_and_stays_in_the_cone():
    """Mean pointing on the source: every sample is x1 g_r(r); |d| <= 15 - r keeps theta <= 15."""
    ekf = ConicalScanEKF()
    x = np.array([[1.0, 0.0, 0.0, 0.0, 0.0]])
    levels = [ekf.h(x, s)[0] for s in ekf.scan]
    np.testing.assert_allclose(levels, (1.0 - scan_loss(4.0)) * ekf.response.peak, rtol=1e-12)
    rng = np.random.default_rng(2)
    d = rng.uniform(-1, 1, (500, 2))
    d *= (11.0 * np.sqrt(rng.random(500)) / np.hypot(d[:, 0], d[:, 1]))[:, None]
    theta = np.hypot(*(d[:, None, :] + ekf.scan[None]).transpose(2, 0, 1))
    assert theta.max() <= 15.0 + 1e-12


def test_closed_loop_boresight_within_mean_error_plus_radius():
    """
    In closed loop on the sphere, theta <= theta_mean + r + 0.2 deg within the cone.

    The mean pointing is the boresight less the joint turn of the scan offset, a
    small-angle construction: the triangle inequality holds to 0.2 deg (measured 0.14).
    """
    from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt
    traj = simulate_pan_tilt(ConicalScanEKF(runs=50), PanTiltLinkConfig(noise=0.5, steps=200), 3)
    inside = traj.theta_mean <= 15.0
    assert np.all((traj.theta <= traj.theta_mean + 4.0 + 0.2)[inside])


@pytest.mark.parametrize('bad', [{'controller': 'pid'}, {'gain': 2.0}, {'points': 2},
                                 {'x0': (1.0, 2.0)}, {'Q': (1, 1, 1, 1, -1)},
                                 {'noise': 0.0, 'model_noise': 0.0}, {'radius': math.inf}])
def test_bad_configs_say_why(bad):
    """Each bad setting is one AlignmentError."""
    with pytest.raises(AlignmentError):
        ConicalEKFConfig(**bad)
