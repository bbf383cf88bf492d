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

"""The URDF of the LED rig has exactly the joints the simulator's JointState names."""

import math
from pathlib import Path
import xml.etree.ElementTree as ET

import pytest

from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import default_parameters

URDF = Path(__file__).resolve().parents[2] / 'urdf' / 'scanning_base.urdf'


def joints():
    root = ET.parse(URDF).getroot()
    return {j.get('name'): j for j in root.iter('joint')}


def test_every_simulated_joint_is_a_moving_joint_of_the_urdf():
    movable = {name for name, j in joints().items() if j.get('type') != 'fixed'}
    assert movable == set(conversions.LED_JOINTS)


def test_the_tree_is_connected_and_rooted_at_world():
    root = ET.parse(URDF).getroot()
    links = {link.get('name') for link in root.iter('link')}
    children = {j.find('child').get('link') for j in joints().values()}
    parents = {j.find('parent').get('link') for j in joints().values()}
    assert links == children | {'world'}
    assert parents <= links and 'world' not in children


def test_the_base_joint_limits_are_the_aligners_default_limits():
    lo, hi = default_parameters()['base_limits']           # degrees
    limit = joints()['base'].find('limit')
    assert float(limit.get('lower')) == pytest.approx(math.radians(lo), abs=1e-4)
    assert float(limit.get('upper')) == pytest.approx(math.radians(hi), abs=1e-4)


# -- the pan-tilt mount (the simulator and the alignment node with axes 2) -----------------

PAN_TILT = URDF.parent / 'pan_tilt_mount.urdf'


def pan_tilt_joints():
    root = ET.parse(PAN_TILT).getroot()
    return {j.get('name'): j for j in root.iter('joint')}


def test_the_pan_tilt_joints_are_the_two_axis_truths_joints():
    from tskf_ros.messages.pan_tilt_messages import OFF_AXIS, truth_joints
    movable = {name for name, j in pan_tilt_joints().items() if j.get('type') != 'fixed'}
    joints = default_parameters()['pan_tilt.joints']
    # every joint of true_angle but off_axis, an angle between two directions, not a joint
    assert movable == set(truth_joints(joints)) - {OFF_AXIS}
    assert [pan_tilt_joints()[j].get('type') for j in joints] == ['revolute', 'revolute']


def test_the_pan_tilt_tree_is_connected_and_rooted_at_world():
    root = ET.parse(PAN_TILT).getroot()
    links = {link.get('name') for link in root.iter('link')}
    children = {j.find('child').get('link') for j in pan_tilt_joints().values()}
    parents = {j.find('parent').get('link') for j in pan_tilt_joints().values()}
    assert links == children | {'world'}
    assert parents <= links and 'world' not in children


def test_the_tilt_joint_limits_are_the_aligners_default_tilt_limits():
    lo, hi = default_parameters()['pan_tilt.tilt_limits']          # degrees
    limit = pan_tilt_joints()['tilt'].find('limit')
    assert float(limit.get('lower')) == pytest.approx(math.radians(lo), abs=1e-4)
    assert float(limit.get('upper')) == pytest.approx(math.radians(hi), abs=1e-4)
    # elevation positive up: a turn about -y lifts the boresight (x) toward +z
    assert pan_tilt_joints()['tilt'].find('axis').get('xyz') == '0 -1 0'
