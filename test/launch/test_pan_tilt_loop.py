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

"""launch_testing: launch/pan_tilt_loop.launch.py starts the two-axis LED loop (axes 2)."""

import unittest

from launch_checks import ExitCodes, launch_description, NAMESPACE, receive, skip_unless_runnable
import pytest

skip_unless_runnable()

import launch_testing  # noqa: E402, I100 - imported only where skip_unless_runnable lets it run
from sensor_msgs.msg import Illuminance  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from tskf_ros.messages import alignment_interface as aligner  # noqa: E402


@pytest.mark.launch_test
def generate_test_description():
    """Start the launch file in a namespace of its own, as `ros2 launch` would."""
    return launch_description('pan_tilt_loop.launch.py')


class TestTheLoopRuns(unittest.TestCase):
    """While it runs: the simulator's intensity reaches the aligner, which commands the mount."""

    def test_the_aligner_publishes_estimates_and_commands(self):
        topics = {f'/{NAMESPACE}/{aligner.INPUT_TOPIC}': Illuminance,
                  f'/{NAMESPACE}/{aligner.OUTPUT_TOPICS["corrected"]}': Float64MultiArray,
                  f'/{NAMESPACE}/{aligner.COMMAND_TOPIC}': Float64MultiArray}
        got = receive(topics)
        for topic, messages in got.items():
            self.assertGreaterEqual(len(messages), 3, topic)
        # two joints: [pan, tilt]
        commands = got[f'/{NAMESPACE}/{aligner.COMMAND_TOPIC}']
        self.assertTrue(all(len(m.data) == 2 for m in commands))


@launch_testing.post_shutdown_test()
class TestShutdown(ExitCodes, unittest.TestCase):
    """After the launch is shut down (SIGINT), both nodes exited cleanly."""
