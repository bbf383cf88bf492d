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

"""
An example test of your own code against tskf_ros's nodes, in-process.

Copy it into your package's test folder: the fixtures ros_context, ros_executor and
start_node and the helper spin_until come with tskf_ros (a pytest plugin), no conftest
needed.  The run stays on localhost, in a ROS domain of its own.
"""

import math

import pytest
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Illuminance, JointState
from tskf_ros.testing import spin_until


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


class GapCounter(Node):
    """Your code: records the received-power samples, to find the gaps between them."""

    def __init__(self, **kwargs):
        super().__init__('gap_counter', **kwargs)
        self.stamps, self.powers, self.truth = [], [], []
        best_effort = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.create_subscription(Illuminance, 'received_power', self.on_sample, best_effort)
        # the simulator's true angle comes at every stamp, delivered or not
        self.create_subscription(JointState, 'true_angle',
                                 lambda m: self.truth.append(seconds(m.header.stamp)), 100)

    def on_sample(self, msg):
        self.stamps.append(seconds(msg.header.stamp))
        self.powers.append(msg.illuminance)

    def longest_gap(self):
        return max(b - a for a, b in zip(self.stamps, self.stamps[1:]))


# run on both of rclpy's executors
@pytest.mark.parametrize('executor_kind', ['single', 'events'])
def test_gap_counter_sees_the_simulated_dropouts(start_node, ros_executor):
    counter = start_node(GapCounter)
    start_node('power_meter_simulator', parameters={
        'rate': 20.0,                 # Hz of stamped samples
        'duration': 5.0,              # s of stamps, then it stops: 100 samples
        'start_time': 1.0,            # s, the first stamp
        'time_factor': 10.0,          # published 10x faster than the stamps advance
        'blockage': 'bernoulli',      # each sample lost with this probability
        'drop_probability': 0.3,
        'seed': 1,
        'wait_for_subscribers': 1,    # sample 0 waits for our subscriber
    })
    # wait on a condition with a deadline, never a sleep
    spin_until(ros_executor, lambda: len(counter.truth) == 100,
               what=lambda: f'100 true angles (got {len(counter.truth)})')

    assert 40 < len(counter.stamps) < 95        # about 70 of the 100 samples arrive
    assert set(counter.stamps) <= set(counter.truth)
    assert all(math.isfinite(p) and p > 0 for p in counter.powers)
    assert counter.longest_gap() >= 2 / 20.0 - 1e-9    # a sample was dropped
