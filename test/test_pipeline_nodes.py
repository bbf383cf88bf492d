"""The simulator node, the in-process demo pipeline, and the nodes as separate processes."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import Illuminance, JointState

from tskf_ros.core.linear_models import owc, run_filter
from tskf_ros.core.time_scales import discrete
from tskf_ros.experiments.demo import summarise
from tskf_ros.messages import conversions
from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
from tskf_ros.owc.estimator_session import NS
from tskf_ros.owc.vibrating_link import OwcLinkConfig, simulate_link
from tskf_ros.tools.demo_collector import arrays, Collector, run_in_process

REPO = Path(__file__).resolve().parent.parent
TIMEOUT = 30.0      # s: a bound on waiting for DDS, never an assertion about timing


def spin_until(executor, condition, what):
    """Spin until condition(); fail after TIMEOUT."""
    deadline = time.monotonic() + TIMEOUT
    while not condition():
        assert time.monotonic() < deadline, \
            f'timed out waiting for {what() if callable(what) else what}'
        executor.spin_once(timeout_sec=0.01)


@pytest.mark.parametrize('publish_invalid', [False, True])
def test_simulator_publishes_the_seeded_stream_with_gaps(ros_context, publish_invalid):
    params = {'seed': 3, 'duration': 120.0, 'time_factor': 200.0, 'start_time': 1.0,
              'knob_max': 1.5, 'knob_initial': 1.0, 'blockage': 'bernoulli',
              'drop_probability': 0.1, 'publish_invalid': publish_invalid,
              'wait_for_subscribers': 1}
    sim = PowerMeterSimulator(context=ros_context, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    client = rclpy.create_node('client', context=ros_context)
    power, truth = [], []
    client.create_subscription(Illuminance, 'received_power', power.append,
                               QoSProfile(depth=1000, reliability=qos_profile_sensor_data
                                          .reliability))
    client.create_subscription(JointState, 'true_angle', truth.append, QoSProfile(depth=1000))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(client)
    try:
        spin_until(executor, lambda: len(truth) == 120 and sim.published == 120, 'the stream')
        spin_until(executor, lambda: True, 'flush')
    finally:
        executor.shutdown()
        sim.destroy_node()
        client.destroy_node()
    cfg = OwcLinkConfig(**{k: v for k, v in params.items()
                           if k in OwcLinkConfig.__dataclass_fields__})
    s = simulate_link(cfg, 120)
    stamps = NS + np.arange(120) * NS
    np.testing.assert_array_equal([conversions.msg_to_angle(m)[0] for m in truth], stamps)
    np.testing.assert_array_equal([conversions.msg_to_angle(m)[1][0] for m in truth], s.theta)
    shown = ~s.blocked & (s.valid | publish_invalid)
    got = [conversions.msg_to_power(m) for m in power]
    np.testing.assert_array_equal([g[0] for g in got], stamps[shown])
    np.testing.assert_array_equal([g[1] for g in got], s.reading[shown])
    assert all(g[2] == 100.0 for g in got)
    # the stream has both kinds of gaps, and invalid readings appear only when asked for
    assert np.any(~s.valid & ~s.blocked) and np.any(s.blocked)
    assert any(g[1] <= 0 for g in got) == publish_invalid


def test_simulator_at_1khz(ros_context):
    sim = PowerMeterSimulator(context=ros_context, parameter_overrides=[
        Parameter('rate', value=1000.0), Parameter('duration', value=0.3),
        Parameter('start_time', value=1.0)])
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    try:
        spin_until(executor, lambda: sim.published == 300, '300 samples')
    finally:
        executor.shutdown()
        sim.destroy_node()
    assert sim.link.count == 300


def test_demo_pipeline_in_process():
    record = run_in_process(duration=60.0, time_factor=200.0, seed=0, timeout=60.0)
    s = summarise(record)
    assert s.samples == 60 and s.predicted == s.published and s.corrected == s.published - 1
    # the estimates are the core filter run offline on the received time scale
    t, y = arrays(record.power)
    ref = run_filter(owc(), discrete(t / NS), y[:, None])
    tp, xp = arrays(record.predicted)
    np.testing.assert_array_equal(tp, t)
    np.testing.assert_allclose(xp, ref.x_pred[:, 0], rtol=0, atol=1e-9)
    assert np.isfinite(s.rms_corrected) and s.rms_corrected < s.rms_predicted


def node_process(module, *args):
    """Start python -m tskf_ros.nodes.<module> with this run's ROS environment."""
    return subprocess.Popen([sys.executable, '-m', f'tskf_ros.nodes.{module}', *args],
                            cwd=REPO, env=dict(os.environ), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def test_estimator_in_another_process(ros_context):
    proc = node_process('timescale_estimator', '--ros-args', '--params-file',
                        str(REPO / 'config' / 'owc_estimator.yaml'))
    client = rclpy.create_node('client', context=ros_context)
    collector = Collector(context=ros_context)
    pub = client.create_publisher(Illuminance, 'received_power', QoSProfile(depth=100))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client)
    executor.add_node(collector)
    stamps = np.array([1.0, 2.0, 3.0, 6.0, 7.0, 8.0, 8.5, 9.0, 13.0, 14.0])
    y = np.random.default_rng(4).normal(180.0, 10.0, stamps.size)
    try:
        spin_until(executor, lambda: pub.get_subscription_count() >= 2
                   and collector.peers_ready(), 'the estimator process')
        # the remote reader may match us a little later than we see it: repeat the first
        # sample until it is estimated (the repeats are duplicates, dropped by the node)
        first = conversions.power_to_msg(int(stamps[0] * NS), y[0], 100.0)
        deadline = time.monotonic() + TIMEOUT
        while not collector.record.predicted:
            assert time.monotonic() < deadline, 'the estimator never answered'
            pub.publish(first)
            for _ in range(10):
                executor.spin_once(timeout_sec=0.01)
        for t, v in zip(stamps[1:], y[1:]):
            pub.publish(conversions.power_to_msg(int(t * NS), v, 100.0))
            executor.spin_once(timeout_sec=0.01)
        spin_until(executor, lambda: len(collector.record.predicted) == stamps.size
                   and len(collector.record.corrected) == stamps.size - 1,
                   lambda: f'the estimates (got {collector.record})')
    finally:
        executor.shutdown()
        client.destroy_node()
        collector.destroy_node()
        proc.send_signal(signal.SIGINT)
        out = proc.communicate(timeout=20)[0]
    assert proc.returncode == 0, out
    assert 'rejected (duplicate)' in out or 'WARN' not in out
    ref = run_filter(owc(), discrete(stamps), y[:, None])
    tp, xp = arrays(collector.record.predicted)
    np.testing.assert_array_equal(tp, (stamps * NS).astype(np.int64))
    np.testing.assert_allclose(xp, ref.x_pred[:, 0], rtol=0, atol=1e-9)
    tc, xc = arrays(collector.record.corrected)
    np.testing.assert_allclose(xc, ref.x_corr[:-1, 0], rtol=0, atol=1e-9)


@pytest.mark.parametrize('module', ['timescale_estimator', 'power_meter_simulator'])
def test_help_exits_0_without_ros(module):
    proc = node_process(module, '--help')
    out = proc.communicate(timeout=60)[0]
    assert proc.returncode == 0 and 'usage' in out


def test_bad_yaml_parameters_exit_1():
    proc = node_process('timescale_estimator', '--ros-args', '-p', 'Q:=[1.0, 2.0]')
    out = proc.communicate(timeout=60)[0]
    assert proc.returncode == 1 and 'Q must have 1 entries' in out
