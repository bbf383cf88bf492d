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

"""The simulated intermittent OWC link (Cai et al. IV-A/B): curve, determinism, blockages."""

import numpy as np
import pytest

from tskf_ros.core.linear_models import OWC_LINEAR_RANGE
from tskf_ros.owc.vibrating_link import (fold, OwcLink, OwcLinkConfig, OwcLinkError, P_MAX,
                                         power_curve, simulate_link, THETA_ZERO)


def test_power_curve_matches_eq2_on_the_linear_range():
    theta = np.linspace(*OWC_LINEAR_RANGE, 50)
    np.testing.assert_allclose(power_curve(theta), -637.35 * theta + 511.97, rtol=0, atol=1e-9)


def test_power_curve_shape_of_fig5():
    theta = np.linspace(-2.0, 2.0, 40001)
    p = power_curve(theta)
    # README: 'at most 270 mW, zero beyond 1.51 rad; continuous'
    assert P_MAX == 270.0 and THETA_ZERO == 1.51
    assert p.max() == pytest.approx(P_MAX)
    assert np.all(p <= P_MAX) and np.all(p >= 0)
    assert np.all(p[np.abs(theta) >= THETA_ZERO] == 0)
    # even, non-increasing in |theta|, continuous (no step larger than the steepest slope)
    np.testing.assert_allclose(p, p[::-1])
    right = p[theta >= 0]
    assert np.all(np.diff(right) <= 1e-12)
    assert np.max(np.abs(np.diff(p))) <= 637.35 * (theta[1] - theta[0]) + 1e-9
    # flat near the peak: within 10 % of P_max up to 0.3 rad
    assert power_curve(0.3) > 0.9 * P_MAX


def test_same_seed_same_stream_in_any_chunking():
    cfg = OwcLinkConfig(seed=7, blockage='gilbert_elliott')
    whole = simulate_link(cfg, 500)
    link = OwcLink(cfg)
    sizes = [1, 0, 3, 17, 100, 379]
    parts = [link.generate(n) for n in sizes]
    for name in ('theta', 'reading', 'blocked', 'bad_state', 't'):
        np.testing.assert_array_equal(np.concatenate([getattr(p, name) for p in parts]),
                                      getattr(whole, name))
    other = simulate_link(OwcLinkConfig(seed=8, blockage='gilbert_elliott'), 500)
    assert not np.array_equal(other.reading, whole.reading)


def test_invalid_readings_are_exactly_those_at_or_below_zero():
    s = simulate_link(OwcLinkConfig(seed=3, knob_max=1.5, knob_initial=1.0), 3000)
    assert np.array_equal(s.valid, s.reading > 0)
    # there are interruptions, they happen far out on the curve, and no light reads 0
    assert 0 < np.count_nonzero(~s.valid) < s.reading.size
    assert np.all(s.theta[~s.valid] > 0.9)
    assert np.all(s.reading[s.power == 0] == 0)
    assert np.all((s.theta >= 0.4141 - 1e-12) & (s.theta <= 0.4141 + 1.5 + 1e-12))


def test_knob_stays_in_its_range_and_fold_reflects():
    s = simulate_link(OwcLinkConfig(seed=1, knob_rate=5.0, knob_step=1.0), 2000)
    assert s.knob.min() >= 0.0 and s.knob.max() <= 1.2
    np.testing.assert_allclose(fold(np.array([-0.1, 0.5, 1.3, 2.5]), 0.0, 1.2),
                               [0.1, 0.5, 1.1, 0.1])


def test_rate_1khz():
    s = simulate_link(OwcLinkConfig(rate=1000.0, seed=2), 2000)
    np.testing.assert_allclose(np.diff(s.t), 1e-3)
    assert np.all(np.isfinite(s.reading))


def test_bernoulli_drop_rate_within_sampling_error():
    p, n = 0.1, 200_000
    s = simulate_link(OwcLinkConfig(seed=11, blockage='bernoulli', drop_probability=p), n)
    assert abs(s.blocked.mean() - p) < 4 * np.sqrt(p * (1 - p) / n)


def test_gilbert_elliott_drop_rate_and_burst_length():
    cfg = OwcLinkConfig(seed=12, blockage='gilbert_elliott', ge_p_gb=0.02, ge_p_bg=0.25,
                        ge_loss_good=0.01, ge_loss_bad=0.9)
    n = 300_000
    s = simulate_link(cfg, n)
    rate = cfg.expected_drop_rate()
    # the channel state is a Markov chain with eigenvalue lam; its mean has the variance
    # of n (1 + lam) / (1 - lam) fewer independent samples
    lam = 1 - cfg.ge_p_gb - cfg.ge_p_bg
    sd = np.sqrt(rate * (1 - rate) / n * (1 + lam) / (1 - lam))
    assert abs(s.blocked.mean() - rate) < 5 * sd
    bad = cfg.ge_p_gb / (cfg.ge_p_gb + cfg.ge_p_bg)
    assert abs(s.bad_state.mean() - bad) < 5 * np.sqrt(bad * (1 - bad) / n * (1 + lam)
                                                       / (1 - lam))
    # bad bursts are geometric with mean 1 / p_bg
    edges = np.diff(np.concatenate([[0], s.bad_state.astype(int), [0]]))
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    assert abs(runs.mean() - 1 / cfg.ge_p_bg) < 5 * np.sqrt(1 - cfg.ge_p_bg) / cfg.ge_p_bg \
        / np.sqrt(runs.size)


@pytest.mark.parametrize('bad', [
    {'rate': 0.0}, {'rate': -1.0}, {'blockage': 'fish'}, {'drop_probability': 1.5},
    {'knob_initial': 5.0}, {'noise_std': float('nan')},
    {'blockage': 'gilbert_elliott', 'ge_p_gb': 0.0, 'ge_p_bg': 0.0}])
def test_bad_link_parameters_are_refused(bad):
    with pytest.raises(OwcLinkError):
        OwcLinkConfig(**bad)
