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
Every node's /diagnostics (one status per task, '<node>: <task>') and INFO status line.

In-process: the statuses are built by the nodes' own diagnostics calls, the status lines
come from a fast status_period on the node's timer (the executor spins until they are
logged; nothing is timed).
"""

from diagnostic_msgs.msg import DiagnosticStatus
from node_helpers import call, spin_until
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.led_link_simulator import LedLinkSimulator
from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator

T0 = 1_700_000_000 * NS


def statuses(msg):
    return conversions.msg_to_diagnostics(msg)


def test_estimator_publishes_one_status_per_task_and_logs_a_status_line(loop, ros_context):
    executor, _, nodes = loop
    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('diagnostic_updater.period', value=3600.0),
        Parameter('status_period', value=0.05)])
    nodes.append(node)
    executor.add_node(node)
    assert node.get_parameter('diagnostic_updater.period').value == 3600.0
    for k in range(3):
        node.session.add(T0 + k * NS, 165.0, now_ns=T0 + k * NS)
    got = statuses(node.diagnostics_message(T0 + 3 * NS))
    assert list(got) == [f'timescale_estimator: {t}' for t in (
        'input frequency', 'timestamp delay', 'filter health', 'time scale')]
    assert got['timescale_estimator: input frequency']['Events in window'] == '3'
    assert got['timescale_estimator: filter health']['Samples received'] == '3'
    # the status line, every status_period
    spin_until(executor, lambda: node.status.logged >= 2, 'status lines')
    line = node.status.log()
    assert 'Hz in, 3 received, 3 accepted' in line and 'reset(s)' in line
    assert 'last estimate [' in line
    # status_period 0: no more lines
    assert node.set_parameters([Parameter('status_period', value=0.0)])[0].successful
    assert node.status.timer is None


def test_a_new_diagnostic_updater_period_retimes_the_diagnostics(loop, ros_context):
    executor, _, nodes = loop
    node = TimescaleEstimator(context=ros_context)
    nodes.append(node)
    assert node.diag_timer.timer_period_ns == NS
    assert node.set_parameters([Parameter('diagnostic_updater.period', value=0.5)])[0] \
        .successful
    assert node.diag_timer.timer_period_ns == NS // 2


def test_paused_alignment_counts_its_samples_and_says_so(loop, ros_context):
    # before: samples were dropped before they were counted, and the diagnostics went
    # to ERROR 'no input yet' while they arrived
    executor, client, nodes = loop
    node = Alignment(context=ros_context, parameter_overrides=[
        Parameter('diagnostic_updater.period', value=3600.0)])
    nodes.append(node)
    executor.add_node(node)
    enable = client.create_client(SetBool, '/alignment/enable')
    assert call(executor, enable, SetBool.Request(data=False)).message == 'paused'
    now = node.get_clock().now().nanoseconds
    for k in range(5):
        node._on_intensity(conversions.intensity_to_msg(now - 10 * NS + k * NS // 20, 2.0))
    got = statuses(node.diagnostics_message(node.get_clock().now().nanoseconds))
    frequency, aligner = got['alignment: input frequency'], got['alignment: aligner']
    assert frequency['Events in window'] == '5'
    assert frequency['level'] != DiagnosticStatus.ERROR[0]
    assert aligner['level'] == DiagnosticStatus.OK[0] and 'paused' in aligner['message']
    assert aligner['Samples received while paused'] == '5'
    assert aligner['Samples used'] == '0' and aligner['Paused'] == 'yes'
    assert 'paused' in node.status.log()


def test_simulators_report_their_output_frequency_and_log_a_status_line(loop, ros_context):
    executor, _, nodes = loop
    fast = [Parameter('status_period', value=0.05),
            Parameter('diagnostic_updater.period', value=0.05)]
    for cls in (PowerMeterSimulator, LedLinkSimulator):
        node = cls(context=ros_context, parameter_overrides=fast)
        nodes.append(node)
        executor.add_node(node)
        spin_until(executor, lambda: node.status.logged >= 1, 'a status line')
        got = statuses(node.publish_diagnostics())
        (name,) = got
        assert name == f'{node.get_name()}: output frequency'
        assert 'Events since startup' in got[name]
        assert 'taken' in node.status.log()


def test_use_fqn_puts_the_namespace_in_every_status_name_and_hardware_id(loop, ros_context):
    # two estimators in /left and /right: diagnostic_updater.use_fqn (as upstream's Updater)
    # tells them apart; without it both say 'timescale_estimator: ...'
    executor, _, nodes = loop
    made = {}
    for ns, use_fqn in (('/left', True), ('/right', True), ('/plain', False)):
        overrides = [Parameter('diagnostic_updater.use_fqn', value=use_fqn)]
        for cls in (TimescaleEstimator, PowerMeterSimulator, Alignment):
            node = cls(context=ros_context, namespace=ns, parameter_overrides=overrides)
            nodes.append(node)
            made[ns, cls] = node
    for (ns, cls), node in made.items():
        msg = node.publish_diagnostics()
        want = f'{ns}/{node.get_name()}' if ns != '/plain' else node.get_name()
        assert msg.status and all(s.name.startswith(f'{want}: ') for s in msg.status), (
            [s.name for s in msg.status])
        # the default hardware_id is the same name (the filter nodes: unless frame_id given)
        frame = '' if cls is PowerMeterSimulator else node.config.frame_id
        assert {s.hardware_id for s in msg.status} == {frame or want}
    left, right = (made[ns, TimescaleEstimator].publish_diagnostics()
                   for ns in ('/left', '/right'))
    assert not {s.name for s in left.status} & {s.name for s in right.status}
    # read-only, as the period: given at start
    node = made['/left', TimescaleEstimator]
    assert not node.set_parameters([Parameter('diagnostic_updater.use_fqn',
                                              value=False)])[0].successful
