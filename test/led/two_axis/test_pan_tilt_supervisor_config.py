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

"""The two-axis supervisor's settings: each bad one is refused with its reason."""

import math

import pytest

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig


@pytest.mark.parametrize('bad, reason', [
    ({'start': 'now'}, 'start must be one of'),
    ({'hold_samples': -1}, 'hold_samples'),
    ({'fade_hold': -1}, 'hold_samples'),
    ({'max_step': 2.0}, 'faster than max_step'),
    ({'fade_look': 5.0}, 'less than the spiral pitch'),
    ({'fade_look': -1.0}, 'fade_look must be >= 0'),
    ({'noise': math.nan}, 'noise must be >= 0'),
    ({'inflate': math.inf}, 'inflate must be >= 0'),
    ({'angle_var': (4.0, 1.0)}, 'angle_var'),
    ({'x1_var': (0.0, 1.0)}, 'x1_var'),
    ({'noise': 0.0}, 'noise and inflate must be > 0'),
    ({'settle': -1}, 'settle'),
])
def test_bad_configs_say_why(bad, reason):
    """Each bad setting is one AlignmentError that names it."""
    with pytest.raises(AlignmentError, match=reason):
        PanTiltSupervisorConfig(**bad)


def test_the_defaults_are_valid_and_resume_after_a_failed_hand_over():
    """The defaults pass their own checks; resume is on, max_step 45 deg per command."""
    config = PanTiltSupervisorConfig()
    assert config.resume
    assert config.max_step == pytest.approx(45.0, abs=0.0)
    assert config.spiral.speed * 1.5 <= config.max_step
