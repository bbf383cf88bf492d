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
