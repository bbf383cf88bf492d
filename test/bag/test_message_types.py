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

"""Message type names are checked before anything is imported; rclpy classes and QoS."""

import subprocess
import sys

import pytest
from rclpy.qos import qos_profile_sensor_data

from tskf_ros.bag.message_types import BagTypeError, message_class, qos_from_rclpy, qos_to_rclpy

from .helpers import TIMEOUT


def test_type_names_are_checked_and_nothing_else_is_imported():
    code = (
        'import sys\n'
        'from tskf_ros.bag.message_types import message_class, BagTypeError\n'
        "for name in ('this/msg/X', 'antigravity/msg/X', 'os/msg/PathLike', "
        "'tskf_ros/msg/X', 'sensor_msgs/msg/../X', 'sensor_msgs/srv/SetCameraInfo', "
        "'Sensor_msgs/msg/X', 'sensor_msgs/msg/illuminance', 'sensor_msgs/msg/Nope'):\n"
        '    try:\n'
        '        message_class(name)\n'
        "        print('ACCEPTED', name)\n"
        '    except BagTypeError as exc:\n'
        "        print('refused:', exc)\n"
        "print(sorted(m for m in ('this', 'antigravity', 'webbrowser') if m in sys.modules))\n")
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[-1] == '[]'
    assert len(lines) == 10 and all(line.startswith('refused: ') for line in lines[:-1]), \
        proc.stdout
    assert 'Zen of Python' not in proc.stdout
    assert lines[0] == 'refused: message type this/msg/X is not installed here ' \
        '(no interface package this)'
    assert lines[6] == "refused: 'Sensor_msgs/msg/X' is not a message type name " \
        '(package/msg/Name)'
    assert message_class('sensor_msgs/msg/Illuminance').__name__ == 'Illuminance'
    with pytest.raises(BagTypeError):
        message_class('os/msg/PathLike')


def test_a_service_or_a_non_message_class_is_refused():
    with pytest.raises(BagTypeError, match='is not a message type name'):
        message_class('std_srvs/srv/Trigger')
    with pytest.raises(BagTypeError, match='not installed here'):
        message_class('sensor_msgs/msg/NoSuchThing')


def test_qos_goes_to_rosbags_and_back():
    qos = qos_from_rclpy(qos_profile_sensor_data)
    assert (qos.depth, qos.reliability.name, qos.durability.name) == (5, 'BEST_EFFORT',
                                                                      'VOLATILE')
    back = qos_to_rclpy(qos, depth=7)
    assert (back.depth, back.reliability, back.durability) == (
        7, qos_profile_sensor_data.reliability, qos_profile_sensor_data.durability)
