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

"""The fixed-layout decoding without rosbags: rclpy's layout of a type is rosbags' layout."""

import pytest

from tskf_ros.bag.cdr import fixed_fields
from tskf_ros.bag.message_types import message_class
from tskf_ros.messages.estimator_interface import INPUT_TYPES
from tskf_ros.messages.fixed_cdr import rclpy_layout

# flat types beyond the measurements: every base type's code, unstamped and stamped
FLAT = ['builtin_interfaces/msg/Time', 'std_msgs/msg/Int8', 'std_msgs/msg/UInt16',
        'std_msgs/msg/Int64', 'std_msgs/msg/UInt64', 'std_msgs/msg/Byte',
        'std_msgs/msg/Char']


@pytest.mark.parametrize('msgtype', list(INPUT_TYPES) + FLAT)
def test_rclpy_layout_is_the_layout_of_rosbags_definitions(msgtype):
    """The same (stamped, [(field, struct code)]) from an independent source of the type."""
    assert rclpy_layout(message_class(msgtype)) == fixed_fields(msgtype)


@pytest.mark.parametrize('msgtype', ['sensor_msgs/msg/TimeReference', 'std_msgs/msg/String',
                                     'sensor_msgs/msg/JointState', 'std_msgs/msg/Bool',
                                     'geometry_msgs/msg/AccelStamped'])
def test_a_type_of_no_flat_fixed_layout_is_refused(msgtype):
    """A string, a sequence, a bool or a nested type (rosbags' layout flattens the last)."""
    with pytest.raises(ValueError, match='has no fixed layout'):
        rclpy_layout(message_class(msgtype))
