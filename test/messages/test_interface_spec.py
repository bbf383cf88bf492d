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

"""The interface declaration's pieces: QoS in words, diagnostic key patterns, lookups."""

import pytest
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)

from tskf_ros.messages.interface_spec import DiagnosticTask, KeyRow, LevelRow, qos_summary
from tskf_ros.messages.node_interfaces import interface, INTERFACES


def test_qos_summary_says_rclpys_profiles_in_words():
    # rclpy's sensor-data profile: best effort, keep last 5 (rmw qos_profile_sensor_data)
    assert qos_summary(qos_profile_sensor_data) == 'best effort, keep last 5'
    assert qos_summary(QoSProfile(depth=10)) == 'reliable, keep last 10'
    latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    assert qos_summary(latched) == 'reliable, keep last 1, transient local'


def test_a_task_allows_its_keys_and_reason_patterns_only():
    task = DiagnosticTask('t', '', (), (KeyRow(('Samples received', 'Rejected (<reason>)',
                                                'skipped_<reason>'), ''),))
    assert task.allows('Samples received') and task.allows('Rejected (gated)')
    assert task.allows('skipped_timeout')
    assert not task.allows('Rejected') and not task.allows('Samples')
    assert not task.allows('Rejected (gated) extra') and not task.allows('skipped_')
    # the parentheses are literal, not a regular expression's group
    assert not task.allows('Rejected gated')


def test_status_names_and_tasks_of_a_declared_node():
    declared = interface('timescale_estimator')
    assert declared.status_names('est') == ['est: input frequency', 'est: timestamp delay',
                                            'est: filter health', 'est: time scale']
    assert declared.task('est: filter health').name == 'filter health'
    with pytest.raises(KeyError):
        declared.task('est: nothing')
    with pytest.raises(ValueError, match='not a node of tskf_ros'):
        interface('talker')
    # with every_topic_parameters() every topic exists: the smoothed estimate needs a lag
    assert declared.every_topic_parameters() == {'smoothing_lag': 1}
    assert all(i.node == name for name, i in INTERFACES.items())


def test_level_names_are_the_declared_levels_once_each_in_order():
    task = DiagnosticTask('t', '', (LevelRow('WARN', 'a', 'x'), LevelRow('ERROR', 'b'),
                                    LevelRow('WARN', 'c'), LevelRow('OK', 'd')), ())
    assert task.level_names() == ['WARN', 'ERROR', 'OK']


def test_every_node_says_what_it_does():
    # the nodes overview (doc/nodes/index.md) shows it next to the node's topics
    assert all(i.purpose and '\n' not in i.purpose for i in INTERFACES.values())
