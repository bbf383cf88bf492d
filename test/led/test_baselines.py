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

"""The baselines of Solanki et al. 2018 (Section V): hill-climbing, three-point averaging (26)."""

import pytest

from tskf_ros import led


def test_three_point_eq26():
    tp = led.ThreePointAveraging(gamma=2.0)
    assert tp.step(0.0, 3.0)[0] == 2.0          # V3 at the origin, turn to +gamma
    assert tp.step(0.05, 2.0)[0] == -4.0        # V1 at +gamma, turn to -gamma
    turn = tp.step(0.10, 1.0)[0]                # V2 at -gamma, back to origin + gamma_p
    assert turn == pytest.approx(2.0 + 2.0 * (2.0 - 1.0) / (2.0 + 1.0 + 3.0))


def test_hill_climbing_reverses_when_intensity_drops():
    hc = led.HillClimbing(gamma=2.0)
    assert hc.step(0.0, 1.0)[0] == 2.0
    assert hc.step(0.05, 1.5)[0] == 2.0
    assert hc.step(0.10, 1.2)[0] == -2.0
    assert hc.step(0.15, None)[0] == 0.0
