"""The simulator node, the in-process demo pipeline, and the nodes as separate processes."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import Illuminance, JointState

from tskf_ros.core.linear_models import owc, run_filter
from tskf_ros.core.time_scales import discrete
from tskf_ros.experiments.demo import summarise
from tskf_ros.messages import conversions
from tskf_ros.nodes.node_base import make_executor
from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
from tskf_ros.owc.estimator_session import NS
from tskf_ros.owc.vibrating_link import OwcLinkConfig, simulate_link
from tskf_ros.tools import demo_collector
from tskf_ros.tools.demo_collector import arrays, Collector, run_in_process, wait_for

REPO = Path(__file__).resolve().parent.parent
# s: a bound on waiting for DDS (discovery, matching, delivery), never an assertion about
# timing; generous for a loaded 2-core machine, it costs nothing when things work
TIMEOUT = 60.0
# s: a sample the estimator process has not answered within this is published again (the
# node drops the repeat as a duplicate): best effort across processes may lose one
RESEND = 0.5


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


@pytest.mark.parametrize('publish_invalid', [False, True])
def test_simulator_publishes_the_seeded_stream_with_gaps(ros_context, executor_kind,
                                                         publish_invalid):
    params = {'seed': 3, 'duration': 120.0, 'time_factor': 200.0, 'start_time': 1.0,
              'knob_max': 1.5, 'knob_initial': 1.0, 'blockage': 'bernoulli',
              'drop_probability': 0.1, 'publish_invalid': publish_invalid,
              'wait_for_subscribers': 1}
    # the reference: the ROS-free link with the same settings
    cfg = OwcLinkConfig(**{k: v for k, v in params.items()
                           if k in OwcLinkConfig.__dataclass_fields__})
    s = simulate_link(cfg, 120)
    shown = ~s.blocked & (s.valid | publish_invalid)
    sim = PowerMeterSimulator(context=ros_context, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    client = rclpy.create_node('client', context=ros_context)
    power, truth = [], []
    # in process (delivered in the publish call) into queues deeper than the whole stream:
    # the test controls the transport, so the best-effort power topic loses nothing here
    client.create_subscription(Illuminance, 'received_power', power.append,
                               QoSProfile(depth=1000, reliability=qos_profile_sensor_data
                                          .reliability))
    client.create_subscription(JointState, 'true_angle', truth.append, QoSProfile(depth=1000))
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(sim)
    executor.add_node(client)
    try:
        # every message the link shows, taken: no flush needed after this
        spin_until(executor, lambda: sim.published == 120 and len(truth) == 120
                   and len(power) == int(shown.sum()),
                   lambda: f'the stream ({sim.published} of 120 samples published, '
                   f'{len(truth)} true angles and {len(power)} of {int(shown.sum())} powers '
                   'received)')
    finally:
        executor.shutdown()
        sim.destroy_node()
        client.destroy_node()
    stamps = NS + np.arange(120) * NS
    np.testing.assert_array_equal([conversions.msg_to_angle(m)[0] for m in truth], stamps)
    # the values cross a float64 message unchanged; the tolerance only states that
    np.testing.assert_allclose([conversions.msg_to_angle(m)[1][0] for m in truth], s.theta,
                               rtol=0, atol=1e-12)
    got = [conversions.msg_to_power(m) for m in power]
    np.testing.assert_array_equal([g[0] for g in got], stamps[shown])
    np.testing.assert_allclose([g[1] for g in got], s.reading[shown], rtol=0, atol=1e-12)
    assert all(g[2] == 100.0 for g in got)
    # the stream has both kinds of gaps, and invalid readings appear only when asked for
    assert np.any(~s.valid & ~s.blocked) and np.any(s.blocked)
    assert any(g[1] <= 0 for g in got) == publish_invalid


def test_simulator_at_1khz(ros_context, executor_kind):
    sim = PowerMeterSimulator(context=ros_context, parameter_overrides=[
        Parameter('rate', value=1000.0), Parameter('duration', value=0.3),
        Parameter('start_time', value=1.0)])
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(sim)
    try:
        spin_until(executor, lambda: sim.published == 300, '300 samples')
    finally:
        executor.shutdown()
        sim.destroy_node()
    assert sim.link.count == 300


def test_demo_pipeline_in_process():
    # one process, one executor: the best-effort power reaches the estimator and the
    # collector within the publish call, into queues (100 and 10 000) deeper than the 60
    # samples, so the exact counts below are not at the mercy of the transport
    record = run_in_process(duration=60.0, time_factor=200.0, seed=0, timeout=TIMEOUT)
    s = summarise(record)
    assert s.samples == 60 and s.predicted == s.published and s.corrected == s.published - 1
    # the estimates are the core filter run offline on the received time scale
    t, y = arrays(record.power)
    ref = run_filter(owc(), discrete(t / NS), y[:, None])
    tp, xp = arrays(record.predicted)
    np.testing.assert_array_equal(tp, t)
    np.testing.assert_allclose(xp, ref.x_pred[:, 0], rtol=0, atol=1e-9)
    assert np.isfinite(s.rms_corrected) and s.rms_corrected < s.rms_predicted


def node_process(module, *args, log):
    """Start python -m tskf_ros.nodes.<module> with this run's ROS environment."""
    # the output goes to a file, not a pipe: a pipe nobody reads while the test runs would
    # block the node once it filled up (every duplicate it drops is a warning line)
    return subprocess.Popen([sys.executable, '-m', f'tskf_ros.nodes.{module}', *args],
                            cwd=REPO, env=dict(os.environ), stdout=log,
                            stderr=subprocess.STDOUT, text=True)


def run_node(module, *args):
    """Run python -m tskf_ros.nodes.<module> to its end; return (exit status, output)."""
    proc = subprocess.run([sys.executable, '-m', f'tskf_ros.nodes.{module}', *args],
                          cwd=REPO, env=dict(os.environ), stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=TIMEOUT)
    return proc.returncode, proc.stdout


def stop(proc, log, sig=signal.SIGINT):
    """Signal the node process (SIGINT), wait (killing it if it hangs); return its output."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        proc.wait(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=TIMEOUT)
        log.seek(0)
        raise AssertionError(f'the node ignored {sig.name} for {TIMEOUT:g} s:\n{log.read()}')
    log.seek(0)
    return log.read()


@pytest.mark.slow
def test_estimator_in_another_process(ros_context, executor_kind, tmp_path):
    log = (tmp_path / 'estimator.log').open('w+')
    # /diagnostics every 0.1 s: its arrival tells that the node has matched our readers
    proc = node_process('timescale_estimator', '--executor', executor_kind, '--ros-args',
                        '--params-file', str(REPO / 'config' / 'owc_estimator.yaml'),
                        '-p', 'diagnostics_period:=0.1',
                        '-r', 'measurement:=received_power', log=log)
    client = rclpy.create_node('client', context=ros_context)
    collector = Collector(context=ros_context)
    # created after the collector's estimate subscriptions: we announce our readers in
    # creation order on one reliable discovery stream, and the node matches each as it
    # reads it; once its /diagnostics writer has matched this later reader (a message
    # arrived), its estimate writers have matched the earlier ones, so no estimate is
    # published before our readers are there to get it
    diagnostics = []
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append,
                               QoSProfile(depth=10))
    pub = client.create_publisher(Illuminance, 'received_power', QoSProfile(depth=100))
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(client)
    executor.add_node(collector)
    stamps = np.array([1.0, 2.0, 3.0, 6.0, 7.0, 8.0, 8.5, 9.0, 13.0, 14.0])
    y = np.random.default_rng(4).normal(180.0, 10.0, stamps.size)
    predicted = collector.record.predicted
    try:
        spin_until(executor, lambda: pub.get_subscription_count() >= 2
                   and collector.peers_ready() and any(
                       s.name.startswith('timescale_estimator') for m in diagnostics
                       for s in m.status),
                   lambda: 'the estimator process (its input matched: '
                   f'{pub.get_subscription_count() >= 2}, its outputs seen: '
                   f'{collector.peers_ready()}, /diagnostics from it: {len(diagnostics)}; '
                   f'exit status {proc.poll()})')
        # one sample at a time, each until it is estimated: our writer may be matched by
        # the node a little after we see its reader, and best effort across processes may
        # lose a sample; a repeat is a duplicate, which the node drops (and says so)
        for t, v in zip(stamps, y):
            stamp = int(t * NS)
            msg = conversions.power_to_msg(stamp, v, 100.0)
            deadline = time.monotonic() + TIMEOUT
            while stamp not in predicted:
                assert time.monotonic() < deadline, \
                    f'the estimator never answered the sample at {t} s (exit {proc.poll()})'
                pub.publish(msg)
                demo_collector.spin_until(executor, lambda: stamp in predicted, RESEND)
        spin_until(executor, lambda: len(collector.record.corrected) == stamps.size - 1,
                   lambda: f'{stamps.size - 1} corrected estimates (got '
                   f'{len(collector.record.corrected)})')
    finally:
        executor.shutdown()
        client.destroy_node()
        collector.destroy_node()
        out = stop(proc, log)
        log.close()
    assert proc.returncode == 0, out
    assert 'rejected (duplicate)' in out or 'WARN' not in out
    ref = run_filter(owc(), discrete(stamps), y[:, None])
    tp, xp = arrays(predicted)
    np.testing.assert_array_equal(tp, (stamps * NS).astype(np.int64))
    np.testing.assert_allclose(xp, ref.x_pred[:, 0], rtol=0, atol=1e-9)
    tc, xc = arrays(collector.record.corrected)
    np.testing.assert_array_equal(tc, (stamps[:-1] * NS).astype(np.int64))
    np.testing.assert_allclose(xc, ref.x_corr[:-1, 0], rtol=0, atol=1e-9)


@pytest.mark.parametrize('module', ['timescale_estimator', 'power_meter_simulator'])
def test_help_exits_0_without_ros(module):
    code, out = run_node(module, '--help')
    assert code == 0 and 'usage' in out


def test_bad_yaml_parameters_exit_1():
    code, out = run_node('timescale_estimator', '--ros-args', '-p', 'Q:=[1.0, 2.0]')
    assert code == 1 and 'Q must have 1 entries' in out
