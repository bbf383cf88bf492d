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

"""An input nobody publishes is named once, with the remap to try; one with a publisher not."""

from node_helpers import spin_until
import rclpy

from tskf_ros.nodes import input_watch
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator


def input_watch_harness(ros_context, monkeypatch, publish_on, delay=3600.0):
    """Build the estimator (input check after delay s), a client publishing on publish_on."""
    from sensor_msgs.msg import Illuminance
    monkeypatch.setattr(input_watch, 'NO_PUBLISHER_DELAY', delay)
    node = TimescaleEstimator(context=ros_context)
    client = rclpy.create_node('input_client', context=ros_context)
    pub = publish_on and client.create_publisher(Illuminance, publish_on, 10)
    executor = make_executor('single', context=ros_context)
    for n in (node, client):
        executor.add_node(n)
    return node, client, pub, executor


def close(executor, *nodes):
    for n in nodes:
        executor.remove_node(n)
    executor.shutdown()
    for n in nodes:
        n.destroy_node()


def test_an_input_nobody_publishes_is_named_once_with_the_remap_to_try(ros_context,
                                                                       monkeypatch):
    node, client, pub, executor = input_watch_harness(ros_context, monkeypatch,
                                                      'received_power')
    try:
        # the check, once the node has discovered the other publisher (its timer: below)
        spin_until(executor, lambda: node.count_publishers('/received_power') > 0,
                   'discovery')
        node.input_watch.check()
        node.input_watch.check()        # once only
        assert node.input_watch.warnings == [
            'no publisher on /measurement (sensor_msgs/msg/Illuminance) after 3600 s: '
            'nothing to filter yet; /received_power has a publisher of that type: try '
            '--ros-args -r /measurement:=/received_power']
    finally:
        close(executor, node, client)


def test_an_input_with_a_publisher_is_not_warned(ros_context, monkeypatch):
    node, client, pub, executor = input_watch_harness(ros_context, monkeypatch,
                                                      'measurement')
    try:
        spin_until(executor, lambda: node.count_publishers('/measurement') > 0, 'discovery')
        node.input_watch.check()
        assert node.input_watch.warnings == []
    finally:
        close(executor, node, client)


def test_the_input_check_runs_on_its_own_after_the_delay(ros_context, monkeypatch):
    # no publisher of Illuminance anywhere in this domain: the warning without a remap
    node, client, _, executor = input_watch_harness(ros_context, monkeypatch, None,
                                                    delay=0.2)
    try:
        spin_until(executor, lambda: node.input_watch.checked, 'the input check')
        assert node.input_watch.warnings == [
            'no publisher on /measurement (sensor_msgs/msg/Illuminance) after 0.2 s: '
            'nothing to filter yet']
    finally:
        close(executor, node, client)
