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

"""The test run is isolated on this machine, and the ros_context fixture works."""

import os


def test_ros_environment_is_isolated():
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert 0 <= int(os.environ['ROS_DOMAIN_ID']) <= 232


def test_ros_context_uses_the_run_domain(ros_context):
    import rclpy

    node = rclpy.create_node('tskf_ros_env_check', context=ros_context)
    try:
        assert ros_context.ok()
        assert ros_context.get_domain_id() == int(os.environ['ROS_DOMAIN_ID'])
    finally:
        node.destroy_node()
