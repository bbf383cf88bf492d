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

"""A StartupWatch looks once, on its own after the delay or when called, and keeps what it said."""

from node_helpers import spin_until
import rclpy

from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.nodes.startup_watch import StartupWatch


class Counting(StartupWatch):
    """A watch whose problems are given, counting the looks."""

    def __init__(self, node, delay, found, **kwargs):
        self.found, self.looks = found, 0
        super().__init__(node, delay, **kwargs)

    def problems(self):
        self.looks += 1
        return list(self.found)


def test_it_looks_once_however_often_it_is_called(ros_context):
    node = rclpy.create_node('watched', context=ros_context)
    try:
        watch = Counting(node, 3600.0, ['one', 'two'])
        assert watch.timer is not None and not watch.checked
        watch.check()
        watch.check()
        assert watch.looks == 1 and watch.warnings == ['one', 'two']
        assert watch.checked and watch.timer is None
    finally:
        node.destroy_node()


def test_it_looks_on_its_own_after_the_delay_on_the_steady_clock(ros_context):
    node = rclpy.create_node('watched', context=ros_context)
    executor = make_executor('single', context=ros_context)
    executor.add_node(node)
    try:
        watch = Counting(node, 0.1, [])
        spin_until(executor, lambda: watch.checked, 'the watch to look')
        assert watch.looks == 1 and watch.warnings == []
    finally:
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_node()


def test_an_unarmed_watch_has_no_timer_but_still_looks_when_called(ros_context):
    node = rclpy.create_node('watched', context=ros_context)
    try:
        watch = Counting(node, 0.1, ['late'], armed=False)
        assert watch.timer is None
        watch.check()
        assert watch.warnings == ['late'] and watch.looks == 1
    finally:
        node.destroy_node()
