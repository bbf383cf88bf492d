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

"""The LED alignment loop in-process (simulator + alignment node), and each bad input."""

import os
from pathlib import Path
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray
from node_helpers import call
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Illuminance, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from tskf_ros import led
from tskf_ros.led.alignment_session import AlignmentConfig, AlignmentSession, NS
from tskf_ros.led.led_link import closed_loop
from tskf_ros.led.pat_config import PatConfig
from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import COMMAND_TOPIC
from tskf_ros.messages.parameters import flat_parameters
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.led_link_simulator import LedLinkSimulator
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.tools.demo_collector import wait_for

import yaml

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config'
# s: only a bound on waiting for DDS (generous: a loaded machine); no assertion depends on
# timing
TIMEOUT = 60.0
DT = 0.05
T0 = 1_700_000_000 * NS
CONVERGED = 40      # samples (2 s) after which |phi| must stay in the tracking zone


def yaml_parameters(name, node, **extra):
    """Parameter overrides from a config/ YAML file, plus extra ones."""
    data = flat_parameters(yaml.safe_load((CONFIG / name).read_text())[node]['ros__parameters'])
    data.update(extra)
    return [Parameter(k, value=v) for k, v in data.items()]


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


# -- the closed loop ----------------------------------------------------------------------


# (algorithm, controller, link, max |phi| after convergence in deg: the EKF's includes its
# +-10 scan; the LQG's scan is +-4 after acquisition)
@pytest.mark.parametrize('algorithm, controller, link, worst', [
    ('ekf', 'p', {'seed': 3}, 11.11),
    ('ekf', 'p', {'seed': 4, 'noise': 1.0, 'blockage': 'gilbert_elliott', 'ge_p_gb': 0.05},
     12.88),
    ('ekf', 'p', {'seed': 5, 'blockage': 'bernoulli', 'drop_probability': 0.3}, 11.08),
    ('ekf', 'lqg', {'seed': 3}, 5.33),
    ('hill_climbing', 'p', {'seed': 6}, 6.40),
    ('three_point', 'p', {'seed': 7}, 6.91),
])
def test_loop_tracks_and_equals_the_core_loop(ros_context, executor_kind, algorithm, controller,
                                              link, worst):
    steps = 400
    sim_params = yaml_parameters('led_link_simulator.yaml', '/**/led_link_simulator', **link,
                                 time_factor=0.0, duration=steps * DT, start_time=1.0,
                                 wait_for_subscribers=1, command_timeout=TIMEOUT)
    sim = LedLinkSimulator(context=ros_context, parameter_overrides=sim_params)
    node = Alignment(context=ros_context, parameter_overrides=yaml_parameters(
        'alignment.yaml', '/**/alignment', algorithm=algorithm, controller=controller))
    # the reference: the ROS-free loop with the same link and session settings
    ref = closed_loop(sim.config.link, AlignmentSession(node.config.session), steps)
    delivered = sum(not s.blocked for s in ref.samples)
    client = rclpy.create_node('client', context=ros_context)
    truth, commands = [], []
    deep = QoSProfile(depth=1000)
    client.create_subscription(JointState, 'true_angle', truth.append, deep)
    client.create_subscription(Float64MultiArray, COMMAND_TOPIC, commands.append, deep)
    # one process, lockstep: each sample waits for the command answering the last (the
    # command timeout, wall clock, is only a bound: a late command would be counted in
    # sim.timeouts), and everything is delivered within the publish call into deep queues
    executor = make_executor(executor_kind, context=ros_context)
    for n in (sim, node, client):
        executor.add_node(n)
    try:
        spin_until(executor, lambda: len(truth) == steps and len(commands) == delivered,
                   lambda: f'the loop ({len(truth)} truth, {len(commands)} commands)')
    finally:
        executor.shutdown()
        for n in (sim, node, client):
            n.destroy_node()
    stamps = [conversions.msg_to_led_truth(m)[0] for m in truth]
    np.testing.assert_array_equal(stamps, NS + np.arange(steps) * int(DT * NS))
    phi = np.array([conversions.msg_to_led_truth(m)[1]['incidence'] for m in truth])
    # the nodes over DDS run exactly the ROS-free loop (same seed, same commands)
    np.testing.assert_allclose(phi, ref.phi(), rtol=0, atol=1e-9)
    sent = [o.command for o in ref.outcomes if o is not None and o.command is not None]
    np.testing.assert_allclose([conversions.msg_to_base_command(m)[0] for m in commands],
                               sent, rtol=0, atol=1e-9)
    assert sim.timeouts == 0 and sim.bad_commands == 0
    # after convergence the receiver stays in the tracking zone (|phi| <= 15 deg)
    assert np.max(np.abs(phi[CONVERGED:])) == pytest.approx(worst, abs=0.005)
    assert worst < led.TRACKING_ANGLE
    assert node.session.stats.received == delivered
    if link.get('blockage', 'none') != 'none':
        assert delivered < steps and node.session.stats.gaps > 0


# -- bad input to the alignment node ------------------------------------------------------


class Harness:
    """The alignment node and a client node (publisher, subscribers) on one executor."""

    def __init__(self, context, overrides, executor_kind):
        self.node = Alignment(context=context, parameter_overrides=overrides)
        self.client = rclpy.create_node('client', context=context)
        self.pub = self.client.create_publisher(Illuminance, 'intensity', QoSProfile(depth=100))
        deep = QoSProfile(depth=1000)
        self.commands, self.predicted, self.corrected, self.diagnostics = [], [], [], []
        self.client.create_subscription(Float64MultiArray, COMMAND_TOPIC, self.commands.append,
                                        deep)
        self.client.create_subscription(Float64MultiArray, 'estimate/predicted',
                                        self.predicted.append, deep)
        self.client.create_subscription(Float64MultiArray, 'estimate/corrected',
                                        self.corrected.append, deep)
        self.client.create_subscription(DiagnosticArray, '/diagnostics',
                                        self.diagnostics.append, 10)
        self.executor = make_executor(executor_kind, context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.client)
        self.spin_until(lambda: self.pub.get_subscription_count() > 0 and all(
            self.client.count_publishers(t) > 0 for t in (
                COMMAND_TOPIC, 'estimate/predicted', 'estimate/corrected')), 'discovery')

    def spin_until(self, condition, what='condition'):
        """Spin until condition() holds; fail (not a timing assertion) after TIMEOUT."""
        spin_until(self.executor, condition, what)

    def send(self, stamp_ns, volts):
        """Publish one sample and wait until the node took it."""
        before = self.node.session.stats.received
        self.pub.publish(conversions.intensity_to_msg(int(stamp_ns), volts, 0.04))
        self.spin_until(lambda: self.node.session.stats.received > before, 'the sample')

    def run(self, samples):
        """Send (stamp ns, volts) samples; wait for the commands the node reports."""
        for t, z in samples:
            self.send(t, z)
        n = self.node.session.stats.commands
        self.spin_until(lambda: len(self.commands) == n and (
            not self.node.session.is_ekf or len(self.corrected) == n), f'{n} outputs')

    def values(self, task='time scale'):
        """Publish the diagnostics now; return one task's level and its key values."""
        self.node.publish_diagnostics()
        n = len(self.diagnostics)
        self.spin_until(lambda: len(self.diagnostics) > n, '/diagnostics')
        msg = self.diagnostics[-1]
        (status,) = [s for s in msg.status if s.name == f'{self.node.get_name()}: {task}']
        return status.level, conversions.msg_to_diagnostics(msg)[status.name]

    def close(self):
        """Destroy the nodes and the executor."""
        self.executor.shutdown()
        self.node.destroy_node()
        self.client.destroy_node()


@pytest.fixture
def make(ros_context, executor_kind):
    """Build a Harness in this test's own context, on each executor; close it afterwards."""
    made = []

    def factory(**extra):
        # no periodic /diagnostics: a timer's message would take ('consume') the counters
        # the test asks for with Harness.values(), at a moment that depends on the load
        extra.setdefault('diagnostic_updater.period', 3600.0)
        h = Harness(ros_context, yaml_parameters('alignment.yaml', '/**/alignment', **extra),
                    executor_kind)
        made.append(h)
        return h
    yield factory
    for h in made:
        h.close()


def at(k):
    """Return the stamp (ns) of nominal sample k: 1 s + k dt."""
    return NS + k * int(DT * NS)


GOOD = [2.9, 2.7, 2.8, 2.5, 2.6, 2.4]


def offline(samples, **config):
    """Run the session offline on (stamp, z) samples; return its outcomes with a command."""
    # the node's parameter file config/alignment.yaml: no supervisor (Table I's loop)
    session = AlignmentSession(AlignmentConfig(**{'pat': PatConfig(enabled=False), **config}))
    return [o for o in (session.add(t, z) for t, z in samples) if o.command is not None]


def check_outputs(h, samples):
    """Check that the node published what the core session gives, and nothing non-finite."""
    ref = offline(samples)
    got = [conversions.msg_to_base_command(m)[0] for m in h.commands]
    np.testing.assert_allclose(got, [o.command for o in ref], rtol=0, atol=1e-9)
    est = [conversions.msg_to_alignment_state(m) for m in h.corrected]
    assert [e.stamp_ns for e in est] == [o.stamp_ns for o in ref]
    for e, o in zip(est, ref):
        np.testing.assert_allclose(e.x, o.posterior[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(e.P, o.posterior[1], rtol=1e-12, atol=1e-9)
    # mu of both: the step into t_k, t_k - t_{k-1} in s (0 at the first sample)
    stamps = [e.stamp_ns for e in est]
    want_mu = [0.0] + [(b - a) / NS for a, b in zip(stamps, stamps[1:])]
    for kind, msgs in (('predicted', h.predicted), ('corrected', h.corrected)):
        read = [conversions.msg_to_state_estimate(m) for m in msgs]
        assert {r.kind for r in read} == {kind}
        assert all(r.names == conversions.ALIGNMENT_STATE_NAMES for r in read)
        assert [r.mu for r in read] == pytest.approx(want_mu, rel=0, abs=1e-12)
        assert all(np.all(np.isfinite(m.data)) for m in msgs)
    assert np.all(np.isfinite(got))
    return est


@pytest.mark.parametrize('bad, reason', [(float('nan'), 'non_finite'),
                                         (float('inf'), 'non_finite'),
                                         (-0.4, 'negative')])
def test_bad_intensity_is_a_missing_sample(make, bad, reason):
    h = make()
    samples = [(at(k), z) for k, z in enumerate(GOOD[:3])] + [(at(3), bad)] + [
        (at(k), z) for k, z in zip((4, 5), GOOD[4:])]
    h.run(samples)
    # every sample gives a command (the scan goes on); the bad one is not used
    assert len(h.commands) == 6
    est = check_outputs(h, samples)
    s = h.node.session.stats
    assert s.missing[reason] == 1 and s.used == 5
    # at the bad sample there is no update: the posterior is the prior
    prior = conversions.msg_to_alignment_state(h.predicted[3])
    np.testing.assert_allclose(est[3].x, prior.x, rtol=0, atol=1e-12)
    _, values = h.values('aligner')
    assert values[f'Missing ({reason})'] == '1'


def test_negative_intensity_used_when_asked(make):
    h = make(negative_is_missing=False)
    h.run([(at(0), 2.9), (at(1), -0.4), (at(2), 2.8)])
    assert h.node.session.stats.used == 3 and not h.node.session.stats.missing


def test_missing_samples_are_predicted_over_with_the_stamps(make):
    h = make()
    ks = [0, 1, 2, 6, 7]                       # samples 3, 4, 5 never arrive: mu = 4
    samples = [(at(k), z) for k, z in zip(ks, GOOD)]
    h.run(samples)
    est = check_outputs(h, samples)
    # P^f = P + mu Q over the gap (the scan index moved once: one command per arrival)
    prior = conversions.msg_to_alignment_state(h.predicted[3])
    Q = np.diag([0.25, 1.0])
    np.testing.assert_allclose(prior.P, est[2].P + 4 * Q, rtol=1e-12, atol=1e-9)
    assert prior.mu == pytest.approx(4 * DT, rel=1e-12)
    s = h.node.session.stats
    assert s.gaps == 1 and s.mu_max == pytest.approx(4.0)
    assert s.gap_max == pytest.approx(0.2)


def test_long_gap_warns(make):
    h = make(max_gap=1.0)
    h.run([(at(0), 2.9), (at(1), 2.8), (at(40), 2.7)])
    level, values = h.values()
    assert level == conversions.LEVELS['WARN'] and values['Gaps'] == '1'
    level, _ = h.values()                         # reported once
    assert level == conversions.LEVELS['OK']


@pytest.mark.parametrize('bad_stamp, reason', [(at(2), 'duplicate'),
                                               (at(1) + 1000, 'stale'),
                                               (0, 'zero_stamp')])
def test_bad_stamp_is_dropped(make, bad_stamp, reason):
    h = make()
    samples = [(at(0), 2.9), (at(1), 2.8), (at(2), 2.7), (bad_stamp, 2.6), (at(3), 2.5)]
    h.run(samples)
    assert len(h.commands) == 4                  # nothing for the dropped sample
    check_outputs(h, samples)
    stamps = [conversions.msg_to_state_estimate(m).stamp_ns for m in h.corrected]
    assert stamps == [at(k) for k in range(4)]
    assert h.node.session.stats.rejected[reason] == 1
    _, values = h.values('aligner')
    assert values[f'Rejected ({reason})'] == '1'


def test_backward_jump_restarts(make):
    h = make(max_backward=5.0)
    h.run([(at(k), 2.9) for k in range(200, 203)] + [(at(1), 2.8), (at(2), 2.7)])
    s = h.node.session.stats
    assert s.resets['backward_jump'] == 1 and len(h.commands) == 5
    # restarted from x0: the prior at the jump is Table I's
    prior = conversions.msg_to_alignment_state(h.predicted[3])
    np.testing.assert_allclose(prior.x, led.PAPER_X0, rtol=0, atol=1e-12)
    assert prior.mu == 0.0          # the first sample of the new run


def test_clock_jump_restarts(make):
    h = make(use_sim_time=True)
    clock_pub = h.client.create_publisher(Clock, '/clock', 10)
    h.spin_until(lambda: clock_pub.get_subscription_count() > 0, '/clock subscriber')
    clock_pub.publish(Clock(clock=conversions.ns_to_stamp(1000 * NS)))
    h.spin_until(lambda: h.node.get_clock().now().nanoseconds == 1000 * NS, 'sim time')
    h.run([(at(0), 2.9), (at(1), 2.8)])
    clock_pub.publish(Clock(clock=conversions.ns_to_stamp(10 * NS)))
    h.spin_until(lambda: h.node.session.stats.resets['clock_jump'] == 1, 'the restart')
    assert h.node.session.last_ns is None


@pytest.mark.parametrize('name, value, reason', [
    ('gain', 0.0, 'need 0 < G < 2'),
    ('gain', 2.5, 'need 0 < G < 2'),
    ('algorithm', 'gradient', 'algorithm must be one of'),
    ('Q', [1.0, 0.0], 'Q must have 4 entries'),
    ('R', [1.0, 0.0, 0.0, -1.0], 'R must be positive definite'),
    ('scan', [0.0, 0.0, 2.0], 'consecutive scan angles must differ'),
])
def test_bad_parameter_is_refused_and_loop_keeps_running(make, name, value, reason):
    h = make()
    h.run([(at(0), 2.9), (at(1), 2.8)])
    result = h.node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and reason in result.reason, result.reason
    h.run([(at(2), 2.7)])
    check_outputs(h, [(at(0), 2.9), (at(1), 2.8), (at(2), 2.7)])


def test_parameter_changes_are_used(make):
    h = make()
    h.run([(at(0), 2.9)])
    assert h.node.set_parameters([Parameter('gain', value=0.3)])[0].successful
    assert h.node.session.aligner.gain == 0.3 and h.node.session.stats.resets.total() == 0
    assert h.node.set_parameters([Parameter('algorithm', value='three_point')])[0].successful
    assert isinstance(h.node.session.aligner, led.ThreePointAveraging)
    assert h.node.session.stats.resets['reconfigured'] == 1
    h.run([(at(1), 2.8)])
    np.testing.assert_allclose(conversions.msg_to_base_command(h.commands[-1]),
                               h.node.session.base, rtol=0, atol=1e-9)


@pytest.mark.parametrize('module', ['alignment', 'led_link_simulator'])
def test_help_exits_0_without_ros(module):
    proc = subprocess.run([sys.executable, '-m', f'tskf_ros.nodes.{module}', '--help'],
                          cwd=REPO, env=dict(os.environ), capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 0 and 'usage' in proc.stdout


def test_bad_parameters_exit_1():
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.alignment', '--ros-args',
                           '-p', 'gain:=-0.001'], cwd=REPO, env=dict(os.environ),
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 1 and 'need 0 < G < 2' in proc.stderr


def test_enable_service_pauses_and_resumes_the_alignment_commands(loop, ros_context):
    executor, client, nodes = loop
    node = Alignment(context=ros_context)
    nodes.append(node)
    executor.add_node(node)
    enable = client.create_client(SetBool, '/alignment/enable')
    assert call(executor, enable, SetBool.Request(data=False)).message == 'paused'
    node._on_intensity(conversions.intensity_to_msg(T0, 2.0))
    stats = node.session.stats
    assert node.paused == stats.paused == stats.received == 1 and stats.commands == 0
    assert call(executor, enable, SetBool.Request(data=True)).message == 'enabled'
    node._on_intensity(conversions.intensity_to_msg(T0 + NS, 2.0))
    assert node.session.stats.commands == 1
    reset = client.create_client(Trigger, '/alignment/reset')
    assert call(executor, reset, Trigger.Request()).success
    assert node.session.stats.resets['service'] == 1
