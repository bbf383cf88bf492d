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

from dataclasses import dataclass, replace
from functools import lru_cache
import math

import numpy as np
import pytest
from sample_filter import SampleFilter
import scipy.stats

from tskf_ros.led.intensity_model import AlignmentError, IncidenceResponse
from tskf_ros.led.scanning_ekf import StampClock
from tskf_ros.led.two_axis.conical_ekf import (ConicalEKFConfig, ConicalScanEKF, CONSISTENT,
                                               scan_loss, transition)
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig
from tskf_ros.led.two_axis.pointing_geometry import closed_scan_turn, joint_turn, tangent_error
from tskf_ros.led.two_axis.radial_response import RadialResponse

NOISE_LEVELS = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)

# the filter alone, without the smoother of its first 100 samples (window_smoother)
ALONE = ConicalEKFConfig(smooth_after=0)


def random_states(rng, runs):
    """States [x1, d_c, d_e, b_c, b_e] of `runs` runs, spread over the tracking cone."""
    return np.column_stack([rng.uniform(0.5, 4.0, runs), rng.uniform(-12, 12, (runs, 2)),
                            rng.normal(0, 0.1, (runs, 2))])


def test_jacobian_matches_finite_differences():
    """H = dh/dx against central differences at random states and scan offsets."""
    rng = np.random.default_rng(0)
    ekf = ConicalScanEKF(runs=50)
    x = random_states(rng, 50)
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


def _drift_bias_at_8_s(ekf: ConicalScanEKF, seed: int) -> np.ndarray:
    """Return the mean over runs of bhat - b after 8 s of closed loop on a noiseless link."""
    plant = PanTiltLink(PanTiltLinkConfig(noise=0.0), runs=ekf.runs, seed=seed)
    for _ in range(161):
        s = plant.sample()
        plant.command_turn(ekf.step(s.t, s.z))
    # the EKF's b is the drift of d, the source's drift with its sign turned
    return np.mean(ekf.x[:, 3:5] + plant.drift(), axis=0)


def test_the_mean_pointing_starts_the_first_scan_offset_behind_the_boresight():
    """
    x0's d is the boresight's error at the first sample; the filter's d starts s_0 behind.

    The mean pointing is the boresight less the scan offset, so a receiver pointed at the
    source (x0's d = 0) has its mean pointing -s_0 off it.  Started at d = 0 instead,
    every run's estimate began r = 4 deg wrong along s_0 (whatever the source's direction), and the
    first seconds' pull left the drift biased: on a noiseless link from 5 deg off, 200
    runs, the mean of bhat_c - b_c at 8 s was -0.0065 to -0.0076 deg per step (seeds 1
    to 3, standard error 0.0007); started s_0 behind, -0.0014 to -0.0024.  The filter
    alone (smooth_after 0): the smoother at 5 s takes the start of before's bias at 8 s
    to -0.0010 to -0.0018 (test_window_smoother.py), today's start's to -0.0004 to -0.0012.
    """
    ekf = ConicalScanEKF(ConicalEKFConfig(x0=(2.0, 1.0, -0.5, 0.0, 0.0)), runs=3)
    np.testing.assert_allclose(ekf.scan_offset, np.tile([4.0, 0.0], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(ekf.x[:, 1:3], np.tile([1.0 - 4.0, -0.5], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(ekf.x_prior, ekf.x, atol=0.0)
    for seed in (1, 2, 3):
        assert np.all(np.abs(_drift_bias_at_8_s(ConicalScanEKF(ALONE, runs=200), seed)) < 0.004)
    at_zero = ConicalScanEKF(ALONE, runs=200)
    at_zero.x[:, 1:3] = 0.0                 # the start of before
    assert _drift_bias_at_8_s(at_zero, 1)[0] < -0.006


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


@dataclass(frozen=True)
class Consistency:
    """
    The ANEES of [x1, d_c, d_e] with its 95 % bands, and the mean NIS with its band.

    anees: the mean NEES over runs and steps; band: that of one step's ANEES over the m
    runs, chi^2(3m)/m; steps_in_band: the fraction of steps whose ANEES over the runs is
    in its own band (Bar-Shalom, Li & Kirubarajan's form, about 0.95 if consistent);
    interval: anees +- 1.96 standard errors of the runs' own means, a 95 % interval of
    the mean NEES (the runs are independent, their steps are not).
    """

    anees: float
    band: tuple[float, float]
    steps_in_band: float
    interval: tuple[float, float]
    nis: float
    nis_band: tuple[float, float]


@lru_cache(maxsize=None)        # the NEES and NIS tests share a run
def _nees_nis(noise, runs=200, steps=300, seed=0, jitter=0.0, dropout=0.0, config=CONSISTENT):
    """
    Run the filter `config` in closed loop at `noise`; return its Consistency over the runs.

    The truth: x1, and the error of the mean pointing (the boresight less the scan offset)
    in the tangent plane at the source.  A run counts until it first leaves the 15 deg
    cone (a stopping time: only its past decides; outside, the light is under the noise
    and x1 and the error trade off): leaving out whole runs that leave later would keep
    only the runs whose errors stayed small.  The first 2 s (the convergence from the wide
    P0) are left out.  The ANEES is the mean of the NEES over runs and steps.  Its band
    is that of one step's ANEES over the m runs in the cone at every step, chi^2(3m)/m
    (Bar-Shalom, Li & Kirubarajan 2001, Sec. 5.4.2): the mean of identically distributed
    steps is less spread than one step (Jensen: it is below one step in the convex
    order), however they are correlated, so this band is a lenient one (not an exact
    95 % region); that of all samples, chi^2(3mK)/(mK), would hold only for independent
    steps.  The NEES
    counts every step (a dropout's too: the estimate is the prior there); the NIS only
    the steps with a sample, from the y and S of the update itself.  The NIS of a
    consistent filter is white, so the mean of its n samples has the band chi^2(n)/n.
    """
    plant = PanTiltLink(PanTiltLinkConfig(noise=noise, jitter=jitter, dropout=dropout),
                        runs=runs, seed=seed)
    ekf = ConicalScanEKF(replace(config, noise=noise), runs=runs)
    nees, nis, theta = (np.empty((steps, runs)) for _ in range(3))
    missing = np.zeros((steps, runs), dtype=bool)
    for k in range(steps):
        s = plant.sample()
        missing[k] = s.missing
        mean = s.joints - joint_turn(ekf.scan_offset, s.joints[:, 1])
        d = tangent_error(mean[:, 0], mean[:, 1], s.source[:, 0], s.source[:, 1])
        turn = ekf.step(s.t, s.z)
        e = ekf.x[:, :3] - np.column_stack([s.x1, d])
        nees[k] = np.einsum('ri,rij,rj->r', e, np.linalg.inv(ekf.P[:, :3, :3]), e)
        nis[k], theta[k] = ekf.nis, s.theta
        plant.command_turn(turn)
    assert np.array_equal(np.isnan(nis), missing)       # the NIS of exactly the samples had
    inside = np.cumprod(theta <= 15.0, axis=0).astype(bool)[40:]
    nees = nees[40:]
    m = int(inside[-1].sum())
    m_k = inside.sum(axis=1)
    per_step = np.where(inside, nees, 0.0).sum(axis=1) / m_k
    lo, hi = (scipy.stats.chi2.ppf(q, 3 * m_k) / m_k for q in (0.025, 0.975))
    counted = inside.sum(axis=0) > 0
    run_means = np.where(inside, nees, 0.0).sum(axis=0)[counted] / inside.sum(axis=0)[counted]
    half = 1.96 * run_means.std(ddof=1) / math.sqrt(run_means.size)
    kept = nis[40:][inside & np.isfinite(nis[40:])]
    n = kept.size
    anees = float(np.mean(nees[inside]))
    return Consistency(anees,
                       tuple(scipy.stats.chi2.ppf([0.025, 0.975], 3 * m) / m),
                       float(np.mean((lo < per_step) & (per_step < hi))),
                       (anees - half, anees + half),
                       float(np.mean(kept)),
                       tuple(scipy.stats.chi2.ppf([0.025, 0.975], n) / n))


@pytest.mark.parametrize('noise', NOISE_LEVELS)
@pytest.mark.parametrize('seed', [0, 5])
def test_nees_is_in_its_band(noise, seed):
    """
    The ANEES of [x1, d] (200 runs) is in its 95 % band at every noise level, seeds 0 and 5.

    CONSISTENT (the Gauss-Hermite regression, 5 points per axis, one pass, the link's
    noise and walks).  The runs' interval (from the runs' spread, not the chi^2
    assumption) holds 3 too, up to 2 V; at 2.5 V it is under 3 on seed 0 (2.44-2.86: a
    little conservative, within the band; doc/design/two_axis.md).
    """
    c = _nees_nis(noise, seed=seed)
    assert c.band[0] < c.anees < c.band[1], c
    if noise < 2.5:
        assert c.interval[0] < 3.0 < c.interval[1], c


@pytest.mark.parametrize('noise', NOISE_LEVELS)
@pytest.mark.parametrize('seed', [9, 13, 17])
def test_nees_is_in_its_band_on_seeds_not_tuned_on(noise, seed):
    """
    The ANEES in its band at every level on seeds 9, 13 and 17, held out.

    The runs' interval does not always hold 3 there (seed 9 at 0 V: 3.09-3.37, a little
    overconfident; at 2.5 V 2.52-3.07), within the band.
    """
    c = _nees_nis(noise, seed=seed)
    assert c.band[0] < c.anees < c.band[1], c


@pytest.mark.parametrize('noise', [
    1.0,
    *(pytest.param(v, marks=pytest.mark.xfail(strict=True, reason=reason)) for v, reason in (
        (0.0, 'measured 1.31 under [2.67, 3.35]'), (0.5, 'measured 2.51 under [2.67, 3.35]'),
        (1.5, 'measured 3.59 over [2.67, 3.35]'), (2.0, 'measured 4.00 over [2.65, 3.37]'),
        (2.5, 'measured 4.03 over [2.62, 3.40]')))])
def test_the_closed_loop_filter_is_consistent_at_1_volt_only(noise):
    """
    The default (closed-loop) filter: the first-order update, R with a 0.2 V floor, Q 0.02.

    Conservative at 0 and 0.5 V (the floor is 60 times what h misses), overconfident from
    1.5 V (the linearisation far off axis).  With its smoother (the default: the first 100
    samples, then every 50; 3.07 at 1 V); the filter alone measured 1.32, 2.53, 3.17 (1 V),
    3.82, 4.40 and 4.47.
    """
    c = _nees_nis(noise, config=ConicalEKFConfig())
    assert c.band[0] < c.anees < c.band[1], c


@pytest.mark.parametrize('noise', [1.0, 1.5, 2.0, 2.5])
def test_with_sigma_points_while_the_prior_is_wide_it_is_consistent_from_1_volt(noise):
    """
    With wide 2.5 deg: the same filter, its runs with a pointing prior over 2.5 deg regressed.

    In its band from 1 to 2.5 V (seed 0: 3.01, 3.19, 2.86, 2.63), where the Jacobian
    alone is overconfident from 1.5 V (3.82, 4.40, 4.47; with the smoother, the test
    above, 3.59, 4.00, 4.03); still conservative at 0 and 0.5 V (1.34 and 2.51: the R
    floor).  The filter alone; with the smoother (the default's) it measured 2.98, 3.26,
    3.24 and 2.68 from 1 to 2.5 V, in the band as well.
    """
    c = _nees_nis(noise, config=replace(ALONE, wide=2.5))
    assert c.band[0] < c.anees < c.band[1], c


def test_a_wide_pointing_prior_is_linearised_by_the_sigma_point_rule():
    """
    Per run: the prior wider than `wide` takes the regression, a narrower one the Jacobian.

    Against the same filter configured wholly one way or the other; a pinned state
    (variance 0) or a prior not positive definite keeps the Jacobian, run by run, and
    wide 0 is the plain EKF.
    """
    base = replace(ConicalEKFConfig(), noise=1.0, wide=2.5)
    ekf = ConicalScanEKF(base, runs=4)
    x = np.array([[1.5, 3.0, -2.0, 0.05, 0.0]] * 4)
    P = np.tile(np.diag([1.0, 9.0, 9.0, 0.004, 0.004]), (4, 1, 1))
    P[1, 1, 1] = P[1, 2, 2] = 4.0                      # sd 2 deg: narrow
    P[2, 1, 1] = 6.26                                  # sd just over 2.5 deg on one axis
    P[3, 2, 2] = P[3, 2, 1] = P[3, 1, 2] = 0.0         # elevation pinned
    offset = np.array([4.0, 0.0])
    got = ekf.linearise(x, P, offset)
    wide, narrow = [0, 2], [1, 3]
    by_rule = ConicalScanEKF(replace(base, linearisation='gauss_hermite_5'),
                             runs=2).linearise(x[wide], P[wide], offset)
    by_jacobian = ConicalScanEKF(replace(base, wide=0.0), runs=4).linearise(x, P, offset)
    for g, r, j in zip(got, by_rule, by_jacobian):
        np.testing.assert_allclose(g[wide], r, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(g[narrow], j[narrow], rtol=1e-12, atol=1e-15)
    assert np.all(by_jacobian[2] == 0.0) and np.all(got[2][wide] > 0.0)   # R_h: what h misses
    at_1 = ConicalScanEKF(replace(base, wide=1.0), runs=1).linearise(x[1:2], P[1:2], offset)
    rule_1 = ConicalScanEKF(replace(base, linearisation='gauss_hermite_5'),
                            runs=1).linearise(x[1:2], P[1:2], offset)
    np.testing.assert_allclose(at_1[0], rule_1[0], rtol=1e-12)        # sd 2 > 1 deg: wide
    P[0, 1, 2] = P[0, 2, 1] = 10.0                     # wide, but not positive definite
    mixed = ekf.linearise(x, P, offset)            # the others as before, per run
    np.testing.assert_allclose(mixed[0][0], by_jacobian[0][0], rtol=1e-12)  # no LinAlgError
    np.testing.assert_allclose(mixed[0][2], by_rule[0][1], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(mixed[0][narrow], by_jacobian[0][narrow], rtol=1e-12, atol=1e-15)


def test_nees_with_jittered_stamps_and_dropouts_at_1_volt():
    """Stamps jittered by up to +-20 ms and 10 % dropouts: the ANEES stays in its band."""
    c = _nees_nis(1.0, jitter=0.02, dropout=0.1)
    assert c.band[0] < c.anees < c.band[1], c


_NIS_OUT = {     # (seed, noise): the mean NIS measured out of its band
    (0, 0.0): 'measured 0.962 under [0.988, 1.012]',
    (0, 0.5): 'measured 0.9873 under [0.9879, 1.0122]',
    (0, 1.0): 'measured 0.985 under [0.988, 1.012]',
    (0, 1.5): 'measured 0.980 under [0.988, 1.012]',
    (0, 2.0): 'measured 0.970 under [0.987, 1.013]',
    (0, 2.5): 'measured 0.957 under [0.987, 1.013]',
    (5, 0.0): 'measured 0.962 under [0.988, 1.012]',
    (5, 2.5): 'measured 0.979 under [0.987, 1.013]'}
# on its band's foot, either way by less than a rounding of the sums may move it
_NIS_EDGE: dict = {}


def _nis_marks(seed: int, noise: float) -> list:
    """Return the xfail marks of (seed, noise): strict out of the band, lenient on its edge."""
    if (seed, noise) in _NIS_OUT:
        return [pytest.mark.xfail(strict=True, reason=_NIS_OUT[seed, noise])]
    if (seed, noise) in _NIS_EDGE:
        return [pytest.mark.xfail(strict=False, reason=_NIS_EDGE[seed, noise])]
    return []


@pytest.mark.parametrize('seed, noise', [
    pytest.param(seed, v, marks=_nis_marks(seed, v)) for seed in (0, 5) for v in NOISE_LEVELS])
def test_nis_in_band(seed, noise):
    """
    The mean NIS of CONSISTENT in the 95 % band of its chi^2, seeds 0 and 5.

    Met from 0.5 to 2 V on seed 5 (and on seeds 9 and 13, not tuned on), on seed 0 at no
    level: its noise draws are 1.2 % under their variance at every level (the levels
    share them).  At 0 and 2.5 V the prior's errors are skewed along H, and with the
    curvature of h this third moment (0 for the Gaussian the filter assumes) makes S 3 to
    4 % and 1 to 2 % too large (doc/design/two_axis.md, "Consistency").
    """
    c = _nees_nis(noise, seed=seed)
    assert c.nis_band[0] < c.nis < c.nis_band[1], c


def test_second_order_update_against_the_moments_of_h():
    """
    Order 2: the predicted sample and S are the moments of h's second-order expansion.

    h(x) + tr(h_xx P)/2 and H P H^T + tr(h_xx P h_xx P)/2 + R: the mean and variance of
    the second-order Taylor expansion of h over x ~ N(xhat, P), from 400 000 samples.
    """
    rng = np.random.default_rng(3)
    ekf = ConicalScanEKF(ConicalEKFConfig(order=2, noise=0.5, model_noise=0.0035), runs=1)
    ekf.x = np.array([[2.5, 3.0, -1.0, 0.02, 0.0]])
    ekf.P = np.diag([0.2, 2.0, 1.5, 1e-3, 1e-3])[None] + 0.1 * np.eye(5)[None]
    P, s = ekf.P[0], ekf.scan_offset
    H = ekf.jacobian(ekf.x, s)[0, 0]
    Hxx = ekf.hessian(ekf.x, s)[0]
    dx = rng.multivariate_normal(np.zeros(5), P, 400_000)
    taylor = ekf.h(ekf.x, s)[0] + dx @ H + 0.5 * np.einsum('ni,ij,nj->n', dx, Hxx, dx)
    z = ekf.h(ekf.x, s)[0] + 0.3
    ekf.update(np.array([z]))
    assert z - ekf.y[0] == pytest.approx(taylor.mean(), abs=4e-3)
    assert ekf.S[0] == pytest.approx(taylor.var() + ekf.R[0, 0, 0], rel=1e-2)


def test_hessian_matches_finite_differences():
    """h_xx against central differences of the Jacobian, at random states and offsets."""
    rng = np.random.default_rng(4)
    ekf = ConicalScanEKF(runs=50)
    x = random_states(rng, 50)
    for offset in ekf.scan[::5]:
        Hxx = ekf.hessian(x, offset)
        for i in range(5):
            up, down = x.copy(), x.copy()
            up[:, i] += 1e-6
            down[:, i] -= 1e-6
            fd = (ekf.jacobian(up, offset) - ekf.jacobian(down, offset))[:, 0, :] / 2e-6
            np.testing.assert_allclose(Hxx[:, :, i], fd, rtol=1e-5, atol=1e-8)


def test_cubature_update_is_filterpys_unscented_update():
    """
    'cubature' against FilterPy's UnscentedKalmanFilter on [x1, d] (b uncorrelated).

    MerweScaledSigmaPoints(3, alpha=1, beta=0, kappa=0) are the cubature points
    x +- sqrt(3) rows of chol(P), weights 1/6; the statistical linear regression with
    R + R_h in core.kalman's update gives FilterPy's x and P, and leaves b alone.
    """
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
    ekf = ConicalScanEKF(replace(CONSISTENT, linearisation='cubature', iterations=1,
                                 noise=0.5), runs=1)
    ekf.x = np.array([[2.5, 3.0, -1.0, 0.02, -0.01]])
    P3 = np.array([[0.3, 0.1, -0.05], [0.1, 2.0, 0.3], [-0.05, 0.3, 1.5]])
    ekf.P = np.zeros((1, 5, 5))
    ekf.P[0, :3, :3], ekf.P[0, 3:, 3:] = P3, 1e-3 * np.eye(2)
    s = ekf.scan_offset
    points = MerweScaledSigmaPoints(3, alpha=1.0, beta=0.0, kappa=0.0)
    ukf = UnscentedKalmanFilter(3, 1, 0.05, lambda x: ekf.h(np.r_[x, 0, 0][None], s),
                                lambda x, dt: x, points)
    ukf.x, ukf.P = ekf.x[0, :3].copy(), P3.copy()
    ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)
    z = float(ekf.h(ekf.x, s)[0]) - 0.4
    ukf.update(np.array([z]), R=ekf.R[0])
    b = ekf.x[0, 3:].copy()
    ekf.update(np.array([z]))
    np.testing.assert_allclose(ekf.x[0, :3], ukf.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ekf.P[0, :3, :3], ukf.P, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ekf.x[0, 3:], b, atol=1e-15)
    assert ekf.S[0] == pytest.approx(float(ukf.S[0, 0]), rel=1e-10)


def test_gauss_hermite_regression_against_samples():
    """
    'gauss_hermite': hx, H and R_h against the regression of h over 400 000 draws of N(x, P).

    The mean of h, Cov(x, h) P^-1 and Var h - H P H^T by Monte Carlo (independent of the
    rule); CONSISTENT's 5 Gauss-Hermite points per axis integrate the smooth g_r to 1 % here.
    """
    rng = np.random.default_rng(6)
    ekf = ConicalScanEKF(replace(CONSISTENT, noise=0.5), runs=1)
    x = np.array([[2.5, 3.0, -1.0, 0.02, 0.0]])
    P = np.diag([0.2, 2.0, 1.5, 1e-3, 1e-3])[None] + 0.1 * np.eye(5)[None]
    s = ekf.scan_offset
    H, hx, R_h = ekf.linearise(x, P, s)
    draws = rng.multivariate_normal(x[0], P[0], 400_000)
    h = ekf.h(draws, s)
    cov = np.cov(draws[:, :3].T, h)
    H_mc = np.linalg.solve(P[0, :3, :3], cov[:3, 3])
    assert hx[0] == pytest.approx(h.mean(), rel=1e-2)
    np.testing.assert_allclose(H[0, 0, :3], H_mc, rtol=2e-2, atol=2e-3)
    assert R_h[0] == pytest.approx(cov[3, 3] - H_mc @ cov[:3, 3], rel=0.1)
    np.testing.assert_allclose(H[0, 0, 3:], 0.0)


@pytest.mark.parametrize('sd, three, five', [(3.0, 0.02, 0.01), (6.0, (0.15, 0.25), 0.04)])
def test_var_h_over_a_wide_pointing_prior_against_samples(sd, three, five):
    """
    Var h over N(x, P) by each Gauss-Hermite rule against 400 000 draws (x1 3.5, d 0).

    The predicted sample's variance H P H^T + R_h, S less R.  A pointing prior sd = 6 deg
    wide (2 to 2.5 V in closed loop) puts the 3-point rule's nodes at +-10.4 deg: it
    overstates Var h by 20 % (measured), most of why the mean NIS was 0.93 at 2.5 V; the
    5-point rule is within 3 %.  At 3 deg both are within 1 %.
    """
    rng = np.random.default_rng(7)
    x = np.array([[3.5, 0.0, 0.0, 0.0, 0.0]])
    P = np.diag([0.25, sd * sd, sd * sd, 1e-3, 1e-3])[None]
    draws = rng.multivariate_normal(x[0], P[0], 400_000)
    var = {}
    for rule in ('gauss_hermite', 'gauss_hermite_5'):
        ekf = ConicalScanEKF(replace(CONSISTENT, linearisation=rule, noise=2.5), runs=1)
        H, _, R_h = ekf.linearise(x, P, ekf.scan_offset)
        var[rule] = float(H[0, 0] @ P[0] @ H[0, 0] + R_h[0]) / ekf.h(draws, ekf.scan_offset).var()
    if isinstance(three, tuple):
        assert three[0] < var['gauss_hermite'] - 1.0 < three[1], var
    else:
        assert var['gauss_hermite'] == pytest.approx(1.0, abs=three), var
    assert var['gauss_hermite_5'] == pytest.approx(1.0, abs=five), var


def test_iterated_ekf_converges_to_the_map_estimate():
    """
    'taylor' order 1, 20 iterations: the Gauss-Newton fixed point of the update.

    The iterated EKF's estimate minimises (x - xp)^T P^-1 (x - xp) + (z - h(x))^2 / R
    (Bell & Cathey, IEEE TAC 1993), so at it P^-1 (x - xp) = H(x)^T (z - h(x)) / R.
    """
    ekf = ConicalScanEKF(ConicalEKFConfig(iterations=20, noise=0.3, model_noise=0.0), runs=1)
    xp = np.array([[2.5, 3.0, -1.0, 0.02, 0.0]])
    P = np.diag([0.2, 2.0, 1.5, 1e-3, 1e-3]) + 0.05 * np.eye(5)
    ekf.x, ekf.P = xp.copy(), P[None].copy()
    s = ekf.scan_offset
    z = float(ekf.h(xp, s)[0]) + 0.5
    ekf.update(np.array([z]))
    x = ekf.x
    gradient = np.linalg.solve(P, (x - xp)[0]) - ekf.jacobian(x, s)[0, 0] * (
        z - float(ekf.h(x, s)[0])) / 0.09
    np.testing.assert_allclose(gradient, 0.0, atol=1e-8)
    once = ConicalScanEKF(ConicalEKFConfig(noise=0.3, model_noise=0.0), runs=1)
    once.x, once.P = xp.copy(), P[None].copy()
    once.update(np.array([z]))
    assert ekf.y[0] == pytest.approx(once.y[0], rel=1e-12)    # the NIS: the prior's
    assert ekf.S[0] == pytest.approx(once.S[0], rel=1e-12)


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

    The correspondence: [x1, d_c, b_c] of the conical EKF (the first-order update,
    order 1) with the LQR is the state
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
        controller='lqr', noise=1.0, model_noise=0.0, dim_radius=0.0, smooth_after=0,
        x0=(2.0, 0.0, 0.0, 0.0, 0.0),
        P0=(1.0, 4.0, 0.0, 0.1, 0.0), Q=(0.0025, 0.01, 0.0, 1e-5, 0.0)), radial, runs=3)
    ekf.scan = np.column_stack([scan, np.zeros(len(scan))])
    # the one-axis filter's prior: its x2 starts at 0 whatever its scan's first point
    # (the conical EKF's d starts at x0's less s_0: the test of the mean pointing's start)
    ekf.x[:, 1:3] = 0.0
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
    ekf = ConicalScanEKF(ConicalEKFConfig(dim_radius=0.0), runs=50)
    traj = simulate_pan_tilt(ekf, PanTiltLinkConfig(noise=0.5, steps=200), 3)
    inside = traj.theta_mean <= 15.0
    assert np.all((traj.theta <= traj.theta_mean + 4.0 + 0.2)[inside])


def test_an_innovation_beyond_the_clip_is_the_predicted_sample_plus_c_sd():
    """
    innovation_clip c: a sample 10 sd off is taken as the prediction + c sqrt(S).

    Against the filter with the clip off given that sample by hand: S = H P H^T + R from
    the Jacobian, written here.
    """
    config = replace(ConicalEKFConfig(), noise=0.2)
    x = np.array([[1.2, 1.5, -0.5, 0.01, 0.0]] * 2)
    P = np.tile(np.diag([0.3, 4.0, 4.0, 0.004, 0.004]), (2, 1, 1))
    clipped, plain = ConicalScanEKF(config, runs=2), ConicalScanEKF(
        replace(config, innovation_clip=0.0), runs=2)
    for ekf in (clipped, plain):
        ekf.x, ekf.P = x.copy(), P.copy()
    offset = clipped.scan_offset
    H = clipped.jacobian(x, np.broadcast_to(offset, (2, 2)))[0, 0]
    zhat = float(clipped.h(x, np.broadcast_to(offset, (2, 2)))[0])
    sd = math.sqrt(float(H @ P[0] @ H) + config.noise ** 2 + config.model_noise ** 2)
    clipped.update(np.array([zhat + 10.0 * sd, zhat - 2.0 * sd]))   # run 1: inside, as is
    plain.update(np.array([zhat + 6.0 * sd, zhat - 2.0 * sd]))
    np.testing.assert_allclose(clipped.x, plain.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(clipped.P, plain.P, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(clipped.nis, [36.0, 4.0], rtol=1e-9)


@pytest.mark.parametrize('clip, inside', [(6.0, 1.0), (0.0, 0.1)])
def test_one_spike_of_30_volts_does_not_lose_the_light(clip, inside):
    """
    A 30 V sample at 4 s on a 3 V link at 0.2 V: with the clip every run tracks on.

    Without it (0) the update turns the pointing tens of degrees off and nearly every run
    is lost at the end (199 of 200 on this seed).  The filter alone (smooth_after 0): the
    smoother at 5 s alone (smooth_every 0), a second after the spike, brought 81 of the 200
    back without the clip.
    """
    from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt
    ekf = ConicalScanEKF(replace(ALONE, noise=0.2, innovation_clip=clip), runs=200)
    spiked = SampleFilter(ekf, lambda stamp, z: np.full_like(z, 30.0)
                          if abs(stamp - 4.0) < 1e-9 else z)
    traj = simulate_pan_tilt(spiked, PanTiltLinkConfig(noise=0.2, steps=400), 3)
    assert (np.mean(traj.theta[-1] <= 15.0) >= inside) == (clip > 0)


@pytest.mark.parametrize('bad', [{'controller': 'pid'}, {'gain': 2.0}, {'points': 2},
                                 {'x0': (1.0, 2.0)}, {'Q': (1, 1, 1, 1, -1)},
                                 {'noise': 0.0, 'model_noise': 0.0}, {'radius': math.inf},
                                 {'order': 3}, {'linearisation': 'ukf'}, {'iterations': 0},
                                 {'dim_radius': -1.0}, {'dim_radius': 15.0},
                                 {'radius': 0.0}, {'radius': 15.0},
                                 {'dim_peak': 0.0}, {'wide': -1.0}, {'wide': math.nan},
                                 {'wide': math.inf}, {'wide_linearisation': 'taylor'},
                                 {'innovation_clip': -1.0}, {'innovation_clip': math.nan}])
def test_bad_configs_say_why(bad):
    """Each bad setting is one AlignmentError."""
    with pytest.raises(AlignmentError):
        ConicalEKFConfig(**bad)


def test_the_scan_widens_per_run_as_the_estimated_peak_falls():
    """dim_radius: each run's r follows dim_scan_radius of its x1hat g_r(0); off: r fixed."""
    from tskf_ros.led.two_axis.scan_radius import dim_scan_radius
    off = ConicalScanEKF(ConicalEKFConfig(dim_radius=0.0), runs=3)
    assert off.scan_offset.shape == (2,)
    assert ConicalEKFConfig().dim_radius == 6.5          # on by default
    config = ConicalEKFConfig(dim_radius=6.5, dim_peak=2.0)
    ekf = ConicalScanEKF(config, runs=4)
    ekf.x[:, 0] = np.array([3.0, 1.5, 0.9, 0.3]) / ekf.response.peak
    np.testing.assert_allclose(np.hypot(*ekf.scan_offset.T), 4.0, rtol=1e-12)
    s_now = ekf.scan_offset.copy()
    turn = ekf.step(0.0, np.full(4, np.nan))
    radius = dim_scan_radius(ekf.x[:, 0] * ekf.response.peak, 4.0, 6.5, 2.0)
    np.testing.assert_allclose(radius, [4.0, 5.25, 6.0, 4.0], rtol=1e-9)
    np.testing.assert_allclose(ekf.scan_offset, radius[:, None] * ekf.unit_scan[1], rtol=1e-12)
    # the mount is sent u and the scan's step from s_k to s_{k+1}, each run with its own
    # radius, closed in joints at the mount's tilt (20 deg at the start)
    np.testing.assert_allclose(turn, closed_scan_turn(ekf.u, s_now, ekf.scan_offset, 20.0),
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize('closed', [False, True])
def test_the_turn_sent_is_u_and_the_scan_step_and_the_tilt_follows_it(closed):
    """closed_scan False: u + s_{k+1} - s_k; True: closed_scan_turn; tilt += the tilt turn."""
    ekf = ConicalScanEKF(ConicalEKFConfig(closed_scan=closed), runs=2, tilt0=35.0)
    tilt = ekf.tilt.copy()
    for k in range(25):
        s_now = ekf.scan_offset.copy()
        turn = ekf.step(0.05 * k, np.array([2.0, 1.5]))
        expected = (closed_scan_turn(ekf.u, s_now, ekf.scan_offset, tilt) if closed
                    else ekf.u + ekf.scan_offset - s_now)
        np.testing.assert_allclose(turn, expected, rtol=0, atol=1e-12)
        tilt = tilt + turn[:, 1]
        np.testing.assert_allclose(ekf.tilt, tilt, rtol=0, atol=1e-12)
    ekf.correct_last_turn(np.array([[0.0, -0.5], [1.0, 0.25]]))
    np.testing.assert_allclose(ekf.tilt, tilt + [-0.5, 0.25], rtol=0, atol=1e-12)


def test_a_dim_scan_keeps_the_boresight_within_the_mean_error_plus_its_radius():
    """With dim_radius the closed loop (supervised, cold start) still scans around its mean."""
    from tskf_ros.led.two_axis.aligners import make_two_axis_aligner
    from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt
    aligner = make_two_axis_aligner('conical_ekf_pat', runs=40, noise=1.0, start='acquiring',
                                    ekf=ConicalEKFConfig(dim_radius=6.5))
    traj = simulate_pan_tilt(aligner, PanTiltLinkConfig(noise=1.0, cone=30.0, steps=200), 4)
    radius = aligner.tracker.radius
    assert radius.min() >= 4.0 and radius.max() <= 6.5 and np.ptp(radius) > 0.0
    inside = traj.theta_mean <= 15.0
    assert np.all((traj.theta <= traj.theta_mean + 6.5 + 0.2)[inside])
    assert np.mean(traj.theta[-20:] <= 15.0) > 0.8


@pytest.mark.parametrize('controller', ['p', 'lqr'])
def test_a_gap_beyond_max_mu_is_refused_and_one_of_years_is_predicted_over(controller):
    """A stamp 1e300 s on: AlignmentError, the filter as it was; 5e7 s on: finite."""
    ekf = ConicalScanEKF(ConicalEKFConfig(controller=controller), runs=3)
    for k in range(10):
        ekf.step(0.05 * k, np.array([2.0, 1.0, np.nan]))
    x, P, stamp = ekf.x.copy(), ekf.P.copy(), ekf.clock.stamp
    with pytest.raises(AlignmentError, match='nominal steps, beyond'):
        ekf.step(1e300, np.array([2.0, 1.0, 0.5]))
    np.testing.assert_array_equal(ekf.x, x)
    np.testing.assert_array_equal(ekf.P, P)
    assert ekf.clock.stamp == stamp
    # 1.6 years (mu = 1e9): the estimate is carried thousands of degrees off, where the
    # response reads no light (not 0 inf = NaN), and every number stays finite
    for gap in (5e7, 5e7 + 0.05):
        turn = ekf.step(stamp + gap, np.array([2.0, 1.0, 0.5]))
        assert np.all(np.isfinite(turn)) and np.all(np.isfinite(ekf.x))
        assert np.all(np.isfinite(ekf.P))
    assert ekf.mu == pytest.approx(1.0, rel=1e-6)
