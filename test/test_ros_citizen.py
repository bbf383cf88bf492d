"""
What a ROS user looks for first: namespaced parameter files, services, state by name.

Also the message's variance as R, a wrong-size measurement, and the model's source.

In-process: each test has its own rclpy Context (the ros_context fixture) and executor.
"""

import math
from pathlib import Path
import time

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool, Trigger

from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import load_config, outcome_messages
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.node_base import make_executor
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator
from tskf_ros.owc.estimator_session import Estimate, EstimatorConfig, EstimatorSession, Outcome
import yaml

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config'
T0 = 1_700_000_000 * NS
TIMEOUT = 30.0


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


def call(executor, client, request):
    """Call a service from a client on the executor; return the response."""
    deadline = time.monotonic() + TIMEOUT
    while not client.service_is_ready():
        assert time.monotonic() < deadline, f'{client.srv_name} never became ready'
        executor.spin_once(timeout_sec=0.05)
    future = client.call_async(request)
    while not future.done():
        assert time.monotonic() < deadline, f'{client.srv_name} never answered'
        executor.spin_once(timeout_sec=0.05)
    return future.result()


@pytest.fixture
def loop(ros_context, executor_kind):
    """Yield an executor (each kind) with a client node; the nodes listed are destroyed after."""
    executor = make_executor(executor_kind, context=ros_context)
    client = rclpy.create_node('citizen_client', context=ros_context)
    executor.add_node(client)
    nodes = [client]
    yield executor, client, nodes
    executor.shutdown()
    for n in nodes:
        n.destroy_node()


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


def test_enable_service_pauses_and_resumes_the_alignment_commands(loop, ros_context):
    executor, client, nodes = loop
    node = Alignment(context=ros_context)
    nodes.append(node)
    executor.add_node(node)
    enable = client.create_client(SetBool, '/alignment/enable')
    assert call(executor, enable, SetBool.Request(data=False)).message == 'paused'
    node._on_intensity(conversions.intensity_to_msg(T0, 2.0))
    assert node.paused == 1 and node.session.stats.received == 0
    assert call(executor, enable, SetBool.Request(data=True)).message == 'enabled'
    node._on_intensity(conversions.intensity_to_msg(T0 + NS, 2.0))
    assert node.session.stats.commands == 1
    reset = client.create_client(Trigger, '/alignment/reset')
    assert call(executor, reset, Trigger.Request()).success
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


def test_the_joint_state_mirror_names_each_state_and_its_standard_deviation():
    config = load_config(CONFIG / 'reference_estimator.yaml')
    x, P = np.array([0.5, -1.25]), np.array([[4.0, 0.3], [0.3, 0.25]])
    out = Outcome('accepted', estimates=[Estimate('corrected', T0, x, P)])
    msgs = dict(outcome_messages(out, config))
    states = msgs[('corrected_states', False)]
    assert list(states.name) == ['position', 'velocity']
    np.testing.assert_allclose(states.position, [0.5, -1.25], rtol=1e-12)
    np.testing.assert_allclose(states.velocity, [2.0, 0.5], rtol=1e-12)      # sqrt(diag P)
    assert conversions.stamp_to_ns(states.header.stamp) == T0
    twist = msgs[('corrected', False)]
    assert states.header.frame_id == twist.header.frame_id == ''


def test_the_message_variance_is_the_measurement_noise_when_asked():
    # independent formulation: a textbook KF step with R_d = the message's variance
    model = owc()
    session = EstimatorSession(EstimatorConfig(model, use_message_variance=True, gate=0.0))
    session.add(T0, 300.0, 25.0)
    out = session.add(T0 + 2 * NS, 310.0, 25.0)       # mu = 2 s
    corrected = [e for e in out.estimates if e.kind == 'corrected'][0]
    x, P, C, D = model.x0, model.P0, model.C, model.D
    S = C @ P @ C.T + 25.0
    K = P @ C.T / S
    x_c = x + K @ (np.array([300.0]) - C @ x - D)
    P_c = (np.eye(1) - K @ C) @ P
    assert corrected.x == pytest.approx(x_c, rel=1e-9)
    assert corrected.P[0, 0] == pytest.approx(P_c[0, 0], rel=1e-9)
    plain = EstimatorSession(EstimatorConfig(model, gate=0.0))
    plain.add(T0, 300.0, 25.0)
    other = [e for e in plain.add(T0 + 2 * NS, 310.0, 25.0).estimates
             if e.kind == 'corrected'][0]
    assert not math.isclose(other.P[0, 0], corrected.P[0, 0], rel_tol=1e-3)  # R / mu used


def test_a_measurement_of_the_wrong_size_is_bad_size():
    session = EstimatorSession(EstimatorConfig(owc()))
    out = session.add(T0, [300.0, 301.0])
    assert (out.status, out.reason) == ('rejected', 'bad_size')
    assert session.diagnostics()[2]['rejected_bad_size'] == 1


def test_the_measurement_topic_takes_the_stamped_scalar_type_a_parameter_names(ros_context):
    from sensor_msgs.msg import Temperature
    from std_msgs.msg import Float64

    from tskf_ros.messages.estimator_interface import ConfigError

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
    with pytest.raises(ConfigError, match='measurement_type must be one of'):
        TimescaleEstimator(context=ros_context, parameter_overrides=[
            Parameter('measurement_type', value='nav_msgs/msg/Odometry')])


def test_the_remap_in_the_owc_launch_file_restores_received_power(ros_context):
    node = TimescaleEstimator(context=ros_context,
                              cli_args=['--ros-args', '-r', 'measurement:=received_power'])
    try:
        assert node.sub.topic_name == '/received_power'
    finally:
        node.destroy_node()


def test_a_parameter_file_that_sets_nothing_is_said_loudly(tmp_path):
    from tskf_ros.nodes.node_base import unused_parameter_file
    wrong = tmp_path / 'wrong.yaml'
    wrong.write_text('some_other_node:\n  ros__parameters:\n    period: 2.0\n')
    for path, expect_warning in ((wrong, True), (CONFIG / 'owc_estimator.yaml', False)):
        argv = ['--ros-args', '--params-file', str(path)]
        context = rclpy.context.Context()
        rclpy.init(context=context, args=argv)
        try:
            node = TimescaleEstimator(context=context)
            try:
                warning = unused_parameter_file(node, argv)
                assert bool(warning) == expect_warning, warning
                if expect_warning:
                    assert 'set none of the parameters of /timescale_estimator' in warning
            finally:
                node.destroy_node()
        finally:
            context.try_shutdown()
