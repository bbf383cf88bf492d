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

"""What the tests that run `record` as a process share: waiting for it, cleaning up."""

import time

import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Illuminance

from tskf_ros.messages import conversions

NS = 1_000_000_000
T0 = 1_700_000_000 * NS


def wait_until_recording(pub, proc, timeout: float, topic: str) -> None:
    """Poll the graph until the recorder process subscribes to pub's topic; fail if it exits."""
    deadline = time.monotonic() + timeout
    while pub.get_subscription_count() == 0:
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, f'the recorder never subscribed to {topic}'
        time.sleep(0.05)          # polling a condition, with a deadline


def stop(proc, node, context) -> None:
    """Kill the recorder if it still runs; destroy the test's node and context."""
    if proc.poll() is None:
        proc.kill()
    node.destroy_node()
    context.try_shutdown()


def latched_source(node_name: str, topic: str, values) -> tuple:
    """
    Return (context, node, publisher) with one Illuminance per value already published.

    Reliable and transient-local: the recorder takes its QoS from the graph, so every
    message reaches it whenever it matches, and the publisher's wait_for_all_acked says
    when all are in its reader (no timing).  Message k is stamped T0 + k s.
    """
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node(node_name, context=context)
    pub = node.create_publisher(Illuminance, topic, QoSProfile(
        depth=100, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    for k, value in enumerate(values):
        pub.publish(conversions.power_to_msg(T0 + k * NS, value, 0.0))
    return context, node, pub
