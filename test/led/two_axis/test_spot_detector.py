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

"""The spot detector's fit: a missing newest sample changes nothing (a dropout during a search)."""

import numpy as np
import pytest

from tskf_ros.led.two_axis.pointing_geometry import off_axis_angle
from tskf_ros.led.two_axis.radial_response import RadialResponse
from tskf_ros.led.two_axis.spot_detector import SpotConfig, SpotDetector


def crossing(detector: SpotDetector, response: RadialResponse, samples: int) -> None:
    """Feed a line of samples past a light at (10, 5) deg, 3 V at its peak, no noise."""
    for k in range(samples):
        position = np.array([[4.0 + 0.5 * k, 4.0]])
        z = 3.0 * response.g(off_axis_angle(position[:, 0], position[:, 1], 10.0, 5.0))
        detector.update(z, position, np.ones(1, dtype=bool))


def test_a_missing_newest_sample_leaves_the_fit_as_it_was():
    response = RadialResponse()
    detector = SpotDetector(SpotConfig(), response, runs=1)
    crossing(detector, response, 20)
    mask = np.ones(1, dtype=bool)
    before = detector.sighting(mask, 1.0)
    # a dropout: the window keeps every sample above (20 < 40) and an empty newest slot
    detector.update(np.array([np.nan]), np.array([[14.0, 4.0]]), mask)
    after = detector.sighting(mask, 1.0)
    assert np.all(np.isfinite(after.center)) and np.all(np.isfinite(after.P))
    np.testing.assert_allclose(after.center, before.center, rtol=0, atol=1e-9)
    np.testing.assert_allclose(after.x1, before.x1, rtol=1e-9)
    # a line of samples along azimuth places the light in azimuth (to the fine grid's
    # step); seen from one side, its elevation trades against its brightness
    assert abs(after.center[0, 0] - 10.0) <= 0.25


def _page_cusum_by_hand(z, k):
    """S_n = max(0, S_{n-1} + z_n - k) (Page 1954), a plain loop; return the largest S."""
    s, top = 0.0, 0.0
    for value in z:
        s = max(0.0, s + value - k)
        top = max(top, s)
    return top


def test_the_threshold_is_three_sigma_of_the_noise_below_one_volt():
    """The threshold h = min(3 V, 3 sigma): 0.6 V at sigma 0.2, 3 V from 1 V (None: 3 V)."""
    response = RadialResponse()
    for noise, h in ((0.2, 0.6), (0.5, 1.5), (1.0198, 3.0), (2.5, 3.0), (None, 3.0)):
        assert SpotDetector(SpotConfig(), response, 1, noise).threshold == pytest.approx(h)


def test_a_noiseless_crossing_is_seen_at_three_sigma_and_missed_at_three_volts():
    """
    A straight pass 7 deg from a 3 V light at 4 deg per sample, no noise.

    The CUSUM (k_ref 1 V) of the pass, by hand, peaks at 2.4 V: the fixed 3 V threshold
    misses it, as the spiral missed lights at 0 V (its curved arms peaked at 2.3 to 2.9
    V); h = 3 sigma (sigma 0.2 V) sees it.
    """
    response = RadialResponse()
    track = np.array([[-40.0 + 4.0 * k, 7.0] for k in range(21)])
    z = 3.0 * response.g(off_axis_angle(track[:, 0], track[:, 1], 0.0, 0.0))
    top = _page_cusum_by_hand(z, 1.0)
    assert top == pytest.approx(2.38, abs=0.01)
    for noise, seen in ((None, False), (0.2, True)):
        detector = SpotDetector(SpotConfig(reference=1.0), response, 1, noise)
        fired = [bool(detector.update(np.array([v]), p[None, :], np.ones(1, dtype=bool))[0])
                 for v, p in zip(z, track)]
        assert any(fired) is seen
        np.testing.assert_allclose(detector.cusum, _last_cusum(z, 1.0), atol=1e-12)


def test_the_default_reference_sees_a_dimmer_crossing_at_three_volts():
    """
    A pass 4 deg from a light dimmed to 2.3 V (the link's x1 walk), no noise, h 3 V.

    By hand the CUSUM with k_ref 1 V peaks at 2.52 V (missed), with the default 0.8 V at
    3.52 V (seen): the light is above 0.8 V for more samples of the pass.
    """
    response = RadialResponse()
    track = np.array([[-40.0 + 4.0 * k, 4.0] for k in range(21)])
    z = 2.3 * response.g(off_axis_angle(track[:, 0], track[:, 1], 0.0, 0.0))
    assert _page_cusum_by_hand(z, 1.0) < 3.0 < _page_cusum_by_hand(z, 0.8)
    assert SpotConfig().reference == 0.8
    detector = SpotDetector(SpotConfig(), response, 1, None)
    fired = [bool(detector.update(np.array([v]), p[None, :], np.ones(1, dtype=bool))[0])
             for v, p in zip(z, track)]
    assert any(fired)
    np.testing.assert_allclose(detector.cusum, _last_cusum(z, 0.8), atol=1e-12)


def _last_cusum(z, k):
    """Return the CUSUM after the last sample, by the same plain loop."""
    s = 0.0
    for value in z:
        s = max(0.0, s + value - k)
    return s
