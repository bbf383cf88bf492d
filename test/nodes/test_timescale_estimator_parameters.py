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
timescale_estimator's parameters and services, as a ROS user meets them.

Namespaced parameter files, the model's source, ~/reset, x0 and P0 set atomically, the
measurement type, the launch file's remap, and absurd parameter changes refused.
In-process: each test has its own rclpy Context (the ros_context fixture) and executor.
"""

import math
from pathlib import Path

from node_helpers import call
import pytest
import rclpy
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator
import yaml

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config'
T0 = 1_700_000_000 * NS
OWC = owc()


def model_name_in(path):
    (section,) = yaml.safe_load(path.read_text()).values()
    return section['ros__parameters']['model_name']


@pytest.mark.parametrize('name', ['owc_estimator.yaml', 'reference_estimator.yaml',
                                  'drogue_estimator.yaml'])
def test_a_namespaced_node_runs_the_model_of_its_parameter_file(name):
    # before: `--params-file reference_estimator.yaml -r __ns:=/ref` silently ran the
    # default OWC model, because the files keyed their section with a bare node name
    context = rclpy.context.Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(CONFIG / name),
                                      '-r', '__ns:=/ref'])
    try:
        node = TimescaleEstimator(context=context)
        try:
            assert node.get_namespace() == '/ref'
            assert node.config.session.model.name == model_name_in(CONFIG / name)
            assert 'parameters (A, ' in node.model_source
        finally:
            node.destroy_node()
    finally:
        context.try_shutdown()


def test_without_parameters_the_node_says_it_runs_the_built_in_model(ros_context):
    node = TimescaleEstimator(context=ros_context)
    try:
        assert node.config.session.model.name == 'owc'
        assert node.model_source.startswith('the built-in default')
    finally:
        node.destroy_node()


def test_the_matrices_given_are_named_and_the_others_hold_their_defaults(ros_context):
    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('C', value=[-600.0]), Parameter('R', value=[100.0])])   # R: as the default
    try:
        assert node.model_source == 'parameters (C, R given)'
        # the matrices not given read back as Cai's model (3), as `ros2 param get` shows them
        assert node.get_parameter('A').value == [1.0]
        assert node.get_parameter('D').value == [511.97]
        assert node.config.session.model.C[0, 0] == -600.0
    finally:
        node.destroy_node()


def test_reset_service_restarts_the_estimator(loop, ros_context):
    executor, client, nodes = loop
    node = TimescaleEstimator(context=ros_context)
    nodes.append(node)
    executor.add_node(node)
    for k in range(5):
        node.session.add(T0 + k * NS, 300.0)
    assert node.session.pending() is not None
    response = call(executor, client.create_client(Trigger, '/timescale_estimator/reset'),
                    Trigger.Request())
    assert response.success
    assert node.session.pending() is None
    assert node.session.stats.resets['service'] == 1


def test_x0_and_p0_set_atomically_set_the_estimate(ros_context):
    node = TimescaleEstimator(context=ros_context)
    try:
        for k in range(5):
            node.session.add(T0 + k * NS, 300.0)
        result = node.set_parameters_atomically([Parameter('x0', value=[0.6]),
                                                 Parameter('P0', value=[0.5])])
        assert result.successful
        assert node.session.stats.resets['set_state'] == 1
        out = node.session.add(T0 + 10 * NS, 300.0)
        (est,) = out.estimates
        assert est.x[0] == pytest.approx(0.6) and est.P[0, 0] == pytest.approx(0.5)
    finally:
        node.destroy_node()


def test_the_measurement_topic_takes_the_stamped_scalar_type_a_parameter_names(ros_context):
    from sensor_msgs.msg import Temperature
    from std_msgs.msg import Float64

    from tskf_ros.messages.parameter_schema import ParameterError

    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('measurement_type', value='sensor_msgs/msg/Temperature')])
    try:
        assert node.sub.msg_type is Temperature and node.sub.topic_name == '/measurement'
        msg = Temperature(temperature=300.0, variance=4.0)
        msg.header.stamp = conversions.ns_to_stamp(T0)
        node._on_measurement(msg)
        assert node.session.pending() == T0
    finally:
        node.destroy_node()
    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('measurement_type', value='std_msgs/msg/Float64')])
    try:
        before = node.get_clock().now().nanoseconds
        node._on_measurement(Float64(data=300.0))
        assert node.session.pending() >= before           # stamped on arrival
    finally:
        node.destroy_node()
    # refused by the schema's one_of<> (a ParameterError: one line at start, see node_base)
    with pytest.raises(ParameterError, match='measurement_type must be one of'):
        TimescaleEstimator(context=ros_context, parameter_overrides=[
            Parameter('measurement_type', value='nav_msgs/msg/Odometry')])


def test_the_remap_in_the_owc_launch_file_restores_received_power(ros_context):
    node = TimescaleEstimator(context=ros_context,
                              cli_args=['--ros-args', '-r', 'measurement:=received_power'])
    try:
        assert node.sub.topic_name == '/received_power'
    finally:
        node.destroy_node()


THETA = 0.5435                      # rad: the OWC model's x0, inside the linear range


def power(theta):
    """Cai eq. (2): the noise-free reading at angle theta."""
    return float(OWC.C[0, 0] * theta + OWC.D[0])


@pytest.fixture
def estimator(ros_context):
    node = TimescaleEstimator(context=ros_context)
    yield node
    node.destroy_node()


def test_node_survives_a_huge_a_after_a_45_s_gap(estimator):
    # before: the change was accepted, then the post-set callback raised OverflowError
    # and the node died
    s = estimator.session
    for k in list(range(5)) + [50, 51]:
        s.add(T0 + k * NS, power(THETA))
    result = estimator.set_parameters([Parameter('A', value=[10000.0])])[0]
    if result.successful:
        assert estimator.config.session.model.A[0, 0] == 10000.0
        times = s.diagnostics()[1].as_dict()
        assert float(times['Theorem 2 peak bound (high)']) == math.inf
    else:
        assert result.reason
    # the node is alive and keeps taking samples
    assert s.add(T0 + 52 * NS, power(THETA)).status in ('accepted', 'rejected', 'reset')


@pytest.mark.parametrize('name, value, why', [
    ('Q', [1e308], 'a step of mu ='),
    ('Q', [1e20], 'state_limit'),
    ('x0', [1e308], 'absurd'),
])
def test_node_refuses_absurd_parameters_with_the_reason(estimator, name, value, why):
    result = estimator.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and why in result.reason
    assert estimator.get_parameter(name).value != value


def test_node_diagnostics_say_error_when_the_input_went_silent(estimator):
    # before: a node whose input had gone silent still reported OK
    from diagnostic_msgs.msg import DiagnosticStatus

    from tskf_ros.messages import conversions
    estimator.session.add(T0, power(THETA), now_ns=T0)
    name = estimator.get_name() + ': input frequency'
    first = conversions.msg_to_diagnostics(estimator.diagnostics_message(T0 + NS))[name]
    assert first['level'] == DiagnosticStatus.OK[0]
    # FrequencyStatus: no event over the last window_size (5) updates is an ERROR
    for k in range(2, 7):
        later = conversions.msg_to_diagnostics(estimator.diagnostics_message(T0 + k * NS))
    assert later[name]['level'] == DiagnosticStatus.ERROR[0]
    assert later[name]['message'] == 'No events recorded.'
