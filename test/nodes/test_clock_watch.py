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

"""A node on use_sim_time with no /clock says so once; with a clock, or without sim time, not."""

from builtin_interfaces.msg import Time
from node_helpers import spin_until
import pytest
import rclpy
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg

from tskf_ros.nodes import clock_watch
from tskf_ros.nodes.led_link_simulator import LedLinkSimulator
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator

SIM_TIME = [Parameter('use_sim_time', value=True)]


@pytest.fixture
def harness(ros_context):
    """Yield an executor, a client node and add(node); every node is destroyed after."""
    executor = make_executor('single', context=ros_context)
    client = rclpy.create_node('clock_client', context=ros_context)
    nodes = [client]

    def add(node):
        nodes.append(node)
        executor.add_node(node)
        return node
    executor.add_node(client)
    yield executor, client, add
    for n in nodes:
        executor.remove_node(n)
    executor.shutdown()
    for n in nodes:
        n.destroy_node()


@pytest.mark.parametrize('make', [TimescaleEstimator, LedLinkSimulator])
def test_sim_time_with_nobody_on_clock_is_said_once_after_the_delay(harness, ros_context,
                                                                    monkeypatch, make):
    executor, _, add = harness
    monkeypatch.setattr(clock_watch, 'NO_CLOCK_DELAY', 0.2)
    node = add(make(context=ros_context, parameter_overrides=SIM_TIME))
    spin_until(executor, lambda: node.clock_watch.checked, 'the check on its timer')
    node.clock_watch.check()            # once only
    assert node.clock_watch.warnings == [
        'use_sim_time is true and the clock still reads 0 after 0.2 s (nobody publishes '
        "/clock): timers do not fire and nothing is stamped; play a bag with 'ros2 bag "
        "play --clock', run a simulator that publishes /clock, or set use_sim_time:=false"]


def test_a_clock_publisher_that_never_publishes_is_named(harness, ros_context, monkeypatch):
    executor, client, add = harness
    monkeypatch.setattr(clock_watch, 'NO_CLOCK_DELAY', 3600.0)
    client.create_publisher(ClockMsg, '/clock', 10)
    node = add(TimescaleEstimator(context=ros_context, parameter_overrides=SIM_TIME))
    spin_until(executor, lambda: node.count_publishers('/clock') > 0, 'discovery')
    node.clock_watch.check()
    assert len(node.clock_watch.warnings) == 1
    assert '(/clock has a publisher, but no message has come)' in node.clock_watch.warnings[0]


def test_a_running_clock_is_not_warned(harness, ros_context, monkeypatch):
    executor, client, add = harness
    monkeypatch.setattr(clock_watch, 'NO_CLOCK_DELAY', 3600.0)
    pub = client.create_publisher(ClockMsg, '/clock', 10)
    node = add(TimescaleEstimator(context=ros_context, parameter_overrides=SIM_TIME))

    def ticked():
        pub.publish(ClockMsg(clock=Time(sec=42)))
        return node.get_clock().now().nanoseconds > 0
    spin_until(executor, ticked, 'the node clock to follow /clock')
    node.clock_watch.check()
    assert node.clock_watch.warnings == []


def test_without_sim_time_there_is_no_check(harness, ros_context):
    _, _, add = harness
    node = add(TimescaleEstimator(context=ros_context))
    assert node.clock_watch.timer is None
    node.clock_watch.check()
    assert node.clock_watch.warnings == []
