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

"""The simulated LED link (tskf_ros.led.led_link): eq. (25) and (5)/(8) one sample at a time."""

import numpy as np
import pytest
from solanki_paper import g_paper

from tskf_ros import led
from tskf_ros.led.led_link import LedLink, LedLinkConfig, LedLinkError


def wrap(angle):
    """Return angle (deg) in [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


def test_a_noise_free_link_is_eq_25_written_out():
    # no noise: phi_k = base_k - bearing_k with bearing_k = -phi0 - beta dt k, x1 fixed, and
    # the photodiode reads x1 g(phi) (eq. (5)/(8)); the base takes a command before the
    # next sample
    cfg = LedLinkConfig(beta=7.0, dt=0.05, noise=0.0, angle_noise=0.0, intensity_walk=0.0,
                        phi0=5.0, max_intensity=3.0)
    link = LedLink(cfg)
    s_unit = led.IncidenceResponse().units_per_degree
    peak = led.IncidenceResponse().peak
    for k in range(1200):
        sample = link.sample()
        base = 0.0 if k <= 50 else 2.0
        phi = wrap(base + 5.0 + 7.0 * 0.05 * k)
        assert sample.index == k and sample.t == pytest.approx(0.05 * k, abs=1e-12)
        assert sample.phi == pytest.approx(phi, abs=1e-9), k
        assert sample.x1 == pytest.approx(3.0 / peak, rel=1e-12)
        assert sample.clean == pytest.approx(3.0 / peak * g_paper(s_unit * phi), rel=1e-12)
        assert sample.reading == sample.clean and not sample.blocked
        if k == 50:
            link.command(2.0)
    with pytest.raises(LedLinkError, match='finite'):
        link.command(float('nan'))


def test_the_same_seed_gives_the_same_samples_and_gilbert_elliott_loses_its_rate():
    cfg = LedLinkConfig(blockage='gilbert_elliott', ge_p_gb=0.05, ge_p_bg=0.2,
                        ge_loss_good=0.0, ge_loss_bad=1.0, seed=4)
    a, b = LedLink(cfg), LedLink(cfg)
    first = [a.sample() for _ in range(20000)]
    assert first[:500] == [b.sample() for _ in range(500)]
    # stationary loss rate pi_bad = p_gb / (p_gb + p_bg) = 0.2; the chain's correlation
    # (1 - p_gb - p_bg = 0.75) makes the sd of the mean about 0.0075 over 20000 samples
    assert cfg.expected_drop_rate() == pytest.approx(0.2)
    lost = np.mean([s.blocked for s in first])
    assert lost == pytest.approx(0.2, abs=0.03)


def test_an_obstructed_beam_reads_the_noise_alone_and_keeps_the_stream():
    # the same seed with and without an obstruction from sample 5 to 9: the readings
    # there are v alone (reading - clean of the clear link), the rest is unchanged
    clear, blocked = LedLink(LedLinkConfig(seed=3)), LedLink(LedLinkConfig(seed=3))
    for k in range(15):
        blocked.obstructed = 5 <= k < 10
        a, b = clear.sample(), blocked.sample()
        assert b.phi == a.phi and b.x1 == a.x1
        if blocked.obstructed:
            assert b.clean == 0.0 and b.reading == pytest.approx(a.reading - a.clean, abs=1e-12)
        else:
            assert (b.clean, b.reading) == (a.clean, a.reading)
