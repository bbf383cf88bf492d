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

"""The two-axis messages: radians on the wire (math.radians by hand), the layout's labels."""

import math

import numpy as np
import pytest

from tskf_ros.messages.conversions import msg_to_state_estimate
from tskf_ros.messages.pan_tilt_messages import (msg_to_pan_tilt_state, msg_to_pan_tilt_truth,
                                                 pan_tilt_command_to_msg, pan_tilt_state_to_msg,
                                                 pan_tilt_truth_to_msg, truth_joints)

STATES = ('x1', 'd_c', 'd_e', 'b_c', 'b_e')
NS = 10**9


def test_the_command_is_pan_then_tilt_in_radians_labelled_with_the_joints():
    msg = pan_tilt_command_to_msg([30.0, -12.5], ('az', 'el'))
    assert list(msg.data) == [math.radians(30.0), math.radians(-12.5)]
    assert msg.layout.dim[0].label == 'az,el' and msg.layout.dim[0].size == 2


def test_the_truth_names_the_joints_the_source_and_the_off_axis_angle():
    msg = pan_tilt_truth_to_msg(5 * NS + 7, [1.0, 20.0], [3.0, 21.0], 2.5, ('pan', 'tilt'))
    assert list(msg.name) == list(truth_joints(('pan', 'tilt'))) == [
        'pan', 'tilt', 'source_azimuth', 'source_elevation', 'off_axis']
    assert list(msg.position) == [math.radians(v) for v in (1.0, 20.0, 3.0, 21.0, 2.5)]
    stamp, angles = msg_to_pan_tilt_truth(msg)
    assert stamp == 5 * NS + 7 and angles['off_axis'] == pytest.approx(2.5, rel=1e-15)


def test_the_estimate_keeps_volts_and_turns_every_angle_to_radians():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(5)
    A = rng.standard_normal((5, 5))
    P = A @ A.T
    msg = pan_tilt_state_to_msg('corrected', 2 * NS, 0.05, x, P, STATES)
    raw = msg_to_state_estimate(msg)
    r = math.pi / 180.0
    scale = np.array([1.0, r, r, r, r])
    np.testing.assert_allclose(raw.x, x * scale, rtol=1e-15, atol=0)
    np.testing.assert_allclose(raw.P, P * np.outer(scale, scale), rtol=1e-15, atol=0)
    assert raw.names == ('x1_intensity_V', 'd_cross_elevation_rad', 'd_elevation_rad',
                         'b_cross_elevation_rad_per_step', 'b_elevation_rad_per_step')
    back = msg_to_pan_tilt_state(msg)
    np.testing.assert_allclose(back.x, x, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(back.P, P, rtol=1e-13, atol=1e-15)
    assert back.kind == 'corrected' and back.mu == 0.05


def test_a_one_axis_estimate_is_not_a_two_axis_one():
    from tskf_ros.messages.conversions import alignment_state_to_msg
    msg = alignment_state_to_msg('corrected', NS, 0.0, np.array([2.0, 1.0]), np.eye(2))
    with pytest.raises(ValueError, match='not a two-axis alignment estimate'):
        msg_to_pan_tilt_state(msg)
