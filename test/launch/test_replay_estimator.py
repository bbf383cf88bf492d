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

"""launch_testing: launch/replay_estimator.launch.py replays a bag into the estimator."""

import unittest

from launch_checks import (assert_each_receives, ExitCodes, launch_description, NAMESPACE,
                           skip_unless_runnable)
import pytest

skip_unless_runnable()

import launch_testing  # noqa: E402, I100 - imported only where skip_unless_runnable lets it run
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import Illuminance  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from tskf_ros.messages import estimator_interface as estimator  # noqa: E402


@pytest.mark.launch_test
def generate_test_description():
    """Start the launch file in a namespace of its own, as `ros2 launch` would."""
    return launch_description('replay_estimator.launch.py')


class TestTheReplayRuns(unittest.TestCase):
    """While it runs: the bag's samples and clock reach the estimator, which publishes."""

    def test_the_estimator_publishes_estimates_of_the_bag(self):
        # the bag's topics in /, the estimator's in the namespace
        topics = {estimator.BAG_POWER_TOPIC: Illuminance,
                  '/clock': Clock,
                  f'/{NAMESPACE}/{estimator.OUTPUT_TOPICS["corrected"]}': Float64MultiArray}
        assert_each_receives(self, topics)


@launch_testing.post_shutdown_test()
class TestShutdown(ExitCodes, unittest.TestCase):
    """The player (at the bag's end, or shut down) and the estimator exited cleanly."""
