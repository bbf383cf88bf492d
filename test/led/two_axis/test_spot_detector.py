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
