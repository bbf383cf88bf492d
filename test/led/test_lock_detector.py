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

"""Loss-of-lock tests, the search sweep and the hand-over fit, against independent forms."""

import numpy as np
import pytest
import scipy.integrate
import scipy.stats

from tskf_ros import led
from tskf_ros.led.acquisition_scan import ExpandingSweep, ScanConfig
from tskf_ros.led.light_detector import DetectorConfig, LightDetector
from tskf_ros.led.lock_detector import (LockConfig, LockDetector, nis_band,
                                        truncated_chi2_moments)

RESPONSE = led.IncidenceResponse()


@pytest.mark.parametrize('gate', [1.5, 3.0, 10.0])
def test_gated_nis_moments_equal_the_integrals(gate):
    # E[e | e < g^2] and Var by quadrature of the chi^2(1) density
    G, f = gate * gate, scipy.stats.chi2(1).pdf
    p = scipy.stats.chi2.cdf(G, 1)
    m1 = scipy.integrate.quad(lambda x: x * f(x), 0, G, points=[1e-9])[0] / p
    m2 = scipy.integrate.quad(lambda x: x * x * f(x), 0, G, points=[1e-9])[0] / p
    got = truncated_chi2_moments(gate)
    assert got.mean == pytest.approx(m1, rel=1e-7)
    assert got.var == pytest.approx(m2 - m1 * m1, rel=1e-6)


def test_ungated_band_is_the_chi_square_quantile():
    for n in (1, 10, 20):
        assert nis_band(n, 1e-3) == pytest.approx(scipy.stats.chi2.isf(1e-3, n), rel=1e-12)
    assert nis_band(0, 1e-3) == 0.0


@pytest.mark.parametrize('gate', [0.0, 2.0, 3.0])
def test_band_false_alarm_rate_by_simulation(gate):
    # sums of 20 chi^2(1) kept by the gate (squares of a normal truncated to +-gate): the
    # share above the band is about alpha (Welch-Satterthwaite is a two-moment fit: within
    # half of alpha, on the conservative side at a tight gate)
    rng = np.random.default_rng(1)
    alpha, n, windows = 0.01, 20, 200_000
    if gate:
        v = scipy.stats.truncnorm(-gate, gate).rvs((windows, n), random_state=rng)
    else:
        v = rng.standard_normal((windows, n))
    total = np.sum(v * v, axis=1)
    rate = float(np.mean(total > nis_band(n, alpha, gate)))
    assert 0.5 * alpha <= rate <= 1.5 * alpha
    if gate == 2.0:
        # without the correction a 2-sigma gate would hide nearly every alarm
        assert np.mean(total > scipy.stats.chi2.isf(alpha, n)) < 0.1 * alpha


def test_m_of_n_low_intensity():
    lock = LockDetector(LockConfig(window=5, low_count=3, corroborate=0, level=0.6), runs=2)
    mask = np.ones(2, dtype=bool)
    none = np.full(2, np.nan)
    verdicts = [lock.update(np.array([z, 2.0]), none, mask).lost
                for z in (0.1, 2.0, 0.1, np.nan, 0.1, 2.0)]
    # run 0: the third low sample among the last five (a missing one counts as neither);
    # then the first low one leaves the window
    assert [bool(v[0]) for v in verdicts] == [False, False, False, False, True, False]
    assert not any(v[1] for v in verdicts)


def test_counted_is_the_nis_values_in_the_window():
    # a missing sample, or one without a NIS, or one outside the mask is not counted;
    # the oldest leaves the window
    lock = LockDetector(LockConfig(window=3, low_count=2, corroborate=0), runs=2)
    seen = []
    for z, nis, on in ((1.0, 0.5, True), (np.nan, 0.5, True), (1.0, np.nan, True),
                       (1.0, 0.5, False), (1.0, 0.5, True), (1.0, 0.5, True)):
        lock.update(np.array([z, 1.0]), np.array([nis, 0.5]), np.array([on, True]))
        seen.append(lock.counted.tolist())
    assert seen == [[1, 1], [1, 2], [1, 3], [0, 3], [1, 3], [2, 3]]


def test_sweep_covers_the_range_in_its_worst_case_travel():
    config = ScanConfig(speed=3.0, first=15.0, pitch=25.0, half_width=90.0)
    sweep = ExpandingSweep(config, runs=1)
    base, travel, lo, hi = np.zeros(1), 0.0, 0.0, 0.0
    mask = np.ones(1, dtype=bool)
    sweep.start(mask, base)
    while not (lo <= -90.0 and hi >= 90.0):
        turn = sweep.turn(base, mask)
        base = base + turn
        travel += abs(float(turn[0]))
        lo, hi = min(lo, base[0]), max(hi, base[0])
        assert abs(turn[0]) <= config.speed + 1e-12
    # legs to +15, -40, +65, -90, +90: 15 + 55 + 105 + 155 + 180 deg
    assert travel == pytest.approx(510.0) == config.worst_case_travel()
    # a cold search is a plain sweep: +90, then -90
    assert config.worst_case_travel(cold=True) == pytest.approx(270.0)


def test_hand_over_fit_recovers_a_clean_beam():
    config = DetectorConfig(window=12)
    det = LightDetector(config, RESPONSE, runs=1)
    bearing, x1 = 23.4, 2.7
    mask = np.ones(1, dtype=bool)
    for b in np.arange(12) * 3.0 + bearing - 16.0:
        det.update(np.array([x1 * RESPONSE.g(b - bearing)]), np.array([b]), mask)
    seen = det.sighting(mask, noise=1.0)
    assert seen.bearing[0] == pytest.approx(bearing, abs=config.grid_step / 2)
    assert seen.x1[0] == pytest.approx(x1, rel=0.02)
    # the covariance is the inverse Fisher information, J by central differences
    b = det.base[0]
    c, a, h = seen.bearing[0], seen.x1[0], 1e-5
    J = np.stack([(RESPONSE.g(b - c) * (a + h) - RESPONSE.g(b - c) * (a - h)) / (2 * h),
                  (a * RESPONSE.g(b - c - h) - a * RESPONSE.g(b - c + h)) / (2 * h)], axis=-1)
    np.testing.assert_allclose(seen.P[0], np.linalg.inv(J.T @ J), rtol=1e-5)
