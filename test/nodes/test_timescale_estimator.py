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

"""timescale_estimator in-process: outputs equal the core run offline, and each bad input."""

from pathlib import Path
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Illuminance
from std_msgs.msg import Float64MultiArray

from tskf_ros.core import rts_smooth
from tskf_ros.core.linear_models import owc, run_filter, spring_mass
from tskf_ros.core.time_scales import discrete
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.parameters import flat_parameters
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator

import yaml

CONFIG = Path(__file__).resolve().parents[2] / 'config'
# the estimate topics (without estimate/smoothed, which only smoothing_lag > 0 makes)
TOPICS = ('predicted', 'corrected', 'revised')
# what the harness keeps: the estimates by topic and kind, and the steps (t_k, mu_k) that
# the predicted estimates carry
OUTPUTS = ('predicted', 'corrected', 'mu', 'revised/predicted', 'revised/corrected',
           'revised/mu')
# 1 Hz with gaps J = 3 (after 4) and J = 4 (after 12), and a dense stretch at 0.25 s
STAMPS = np.array([1, 2, 3, 4, 7, 8, 9, 10, 11, 12, 16, 16.25, 16.5, 16.75, 17, 18, 19, 20])
TIMEOUT = 60.0      # s: only a bound on waiting for DDS; no assertion depends on timing


def yaml_parameters(name, **extra):
    """Parameter overrides from a config/ YAML file, plus extra ones."""
    data = flat_parameters(yaml.safe_load((CONFIG / name).read_text())[
        '/**/timescale_estimator']['ros__parameters'])
    data.update(extra)
    return [Parameter(k, value=v) for k, v in data.items()]


class Harness:
    """The estimator and a client node (publisher, subscribers) on one executor."""

    def __init__(self, context, overrides, executor_kind, *, best_effort=False):
        self.node = TimescaleEstimator(context=context, parameter_overrides=overrides)
        self.client = rclpy.create_node('client', context=context)
        qos = qos_profile_sensor_data if best_effort else QoSProfile(depth=100)
        self.pub = self.client.create_publisher(Illuminance, 'measurement', qos)
        self.got = {k: [] for k in OUTPUTS}
        for topic in TOPICS:
            self.client.create_subscription(Float64MultiArray, 'estimate/' + topic,
                                            self._keep(topic), QoSProfile(depth=1000))
        self.diagnostics = []
        self.client.create_subscription(DiagnosticArray, '/diagnostics',
                                        self.diagnostics.append, 10)
        self.executor = make_executor(executor_kind, context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.client)
        self.spin_until(lambda: self.pub.get_subscription_count() > 0 and all(
            self.client.count_publishers('estimate/' + t) > 0 for t in TOPICS))

    def _keep(self, topic):
        def keep(msg):
            e = conversions.msg_to_state_estimate(msg)
            prefix = 'revised/' if topic == 'revised' else ''
            self.got[prefix + e.kind].append(e)
            if e.kind == 'predicted' and e.mu > 0:      # the step t_k -> t_{k+1}, mu_k
                self.got[prefix + 'mu'].append((e.stamp_ns - round(e.mu * NS), e.mu))
        return keep

    def spin_until(self, condition, what='condition'):
        """Spin until condition() holds; fail (not a timing assertion) after TIMEOUT."""
        deadline = time.monotonic() + TIMEOUT
        while not condition():
            assert time.monotonic() < deadline, f'timed out waiting for {what}'
            self.executor.spin_once(timeout_sec=0.01)

    def send(self, t, power, variance=0.0):
        """Publish one sample (t in s, or an int in ns) and wait until the node took it."""
        before = self.node.session.stats.received
        stamp = t if isinstance(t, int) else int(round(t * NS))
        self.pub.publish(conversions.power_to_msg(stamp, power, variance))
        self.spin_until(lambda: self.node.session.stats.received > before, 'the sample')

    def expect(self, **counts):
        """Wait until each output topic has received count messages."""
        self.spin_until(lambda: all(len(self.got[k.replace('_', '/')]) >= n
                                    for k, n in counts.items()), f'outputs {counts}')

    def estimates(self, topic, n):
        """(stamps s, x, P) received on an estimate topic."""
        out = self.got[topic]
        assert all(e.x.size == n for e in out)
        return (np.array([e.stamp_ns / NS for e in out]), np.array([e.x for e in out]),
                np.array([e.P for e in out]))

    def close(self):
        """Take the nodes off the executor, shut it down, then destroy the nodes."""
        # in this order: a node destroyed while an executor still holds its entities could
        # wait for them for ever (seen once, on a loaded machine)
        for node in (self.node, self.client):
            self.executor.remove_node(node)
        self.executor.shutdown()
        self.node.destroy_node()
        self.client.destroy_node()


@pytest.fixture
def make(ros_context, executor_kind):
    """Build a Harness in this test's own context, on each executor; close it afterwards."""
    made = []

    def factory(overrides=None, **kwargs):
        # no periodic /diagnostics (it would consume the counters a test reads, at a moment
        # that depends on the load)
        quiet = [Parameter('diagnostic_updater.period', value=3600.0)]
        given = overrides or yaml_parameters('owc_estimator.yaml')
        names = {p.name for p in given}
        h = Harness(ros_context, given + [p for p in quiet if p.name not in names],
                    executor_kind, **kwargs)
        made.append(h)
        return h
    yield factory
    for h in made:
        h.close()


def measurements(model, t, seed=0):
    """Noisy measurements of a state near x0 at the points t (seeded)."""
    rng = np.random.default_rng(seed)
    x = model.x0 + 0.02 * rng.standard_normal((t.size, model.x0.size))
    y = x @ model.C.T + (0 if model.D is None else model.D)
    return y + np.sqrt(np.diag(model.R)) * rng.standard_normal(y.shape)


@pytest.mark.parametrize('config, model, transition', [
    ('owc_estimator.yaml', owc(), 'euler'),
    ('reference_estimator.yaml', spring_mass(), 'exact')])
def test_outputs_equal_offline_run(make, config, model, transition):
    h = make(yaml_parameters(config))
    y = measurements(model, STAMPS)
    for t, yi in zip(STAMPS, y[:, 0]):
        h.send(t, yi)
    N = STAMPS.size
    h.expect(predicted=N, corrected=N - 1, mu=N - 1)
    ref = run_filter(model, discrete(STAMPS), y, transition=transition)
    n = model.x0.size
    t, x, P = h.estimates('predicted', n)
    np.testing.assert_array_equal(t, STAMPS)
    np.testing.assert_allclose(x, ref.x_pred, rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, ref.P_pred, rtol=0, atol=1e-9)
    t, x, P = h.estimates('corrected', n)
    np.testing.assert_array_equal(t, STAMPS[:-1])
    np.testing.assert_allclose(x, ref.x_corr[:-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, ref.P_corr[:-1], rtol=0, atol=1e-9)
    mu = h.got['mu']
    np.testing.assert_array_equal([m[0] / NS for m in mu], STAMPS[:-1])
    np.testing.assert_allclose([m[1] for m in mu], np.diff(STAMPS), rtol=0, atol=1e-12)
    assert not any(h.got[k] for k in ('revised/predicted', 'revised/corrected', 'revised/mu'))
    assert h.node.session.stats.accepted == N


def run_with(h, bad, *, before=(1.0, 2.0), after=4.0):
    """Send good samples, then the bad one(s), then a good one; return the stamps seen."""
    for t in before:
        h.send(t, 200.0)
    for args in bad:
        h.send(*args)
    h.send(after, 200.0)
    h.expect(predicted=len(before) + 1, corrected=len(before), mu=len(before))
    return h.estimates('predicted', 1)[0], h.estimates('corrected', 1)[0]


def rejected(h, reason):
    """Return the node's count of samples rejected for reason."""
    return h.node.session.stats.rejected[reason]


def test_nan_power_is_rejected(make):
    h = make()
    pred, corr = run_with(h, [(3.0, float('nan'))])
    np.testing.assert_array_equal(pred, [1, 2, 4])
    np.testing.assert_array_equal(corr, [1, 2])
    assert rejected(h, 'non_finite') == 1


def test_infinite_power_is_rejected(make):
    h = make()
    pred, _ = run_with(h, [(3.0, float('inf')), (3.5, float('-inf'))])
    np.testing.assert_array_equal(pred, [1, 2, 4])
    assert rejected(h, 'non_finite') == 2


def test_nonpositive_power_is_a_gap(make):
    h = make()
    pred, _ = run_with(h, [(3.0, 0.0), (3.5, -5.0)], after=5.0)
    np.testing.assert_array_equal(pred, [1, 2, 5])
    h.expect(mu=2)
    assert h.got['mu'][-1] == (2 * NS, 3.0)      # J = 3
    assert rejected(h, 'invalid_power') == 2
    times = h.node.session.diagnostics()[1].as_dict()
    assert times['Gaps'] == '1' and times['Longest gap J (s)'] == '3.0'


def test_duplicate_stamp_is_dropped(make):
    h = make()
    pred, corr = run_with(h, [(2.0, 201.0)])
    np.testing.assert_array_equal(pred, [1, 2, 4])
    np.testing.assert_array_equal(corr, [1, 2])
    assert rejected(h, 'duplicate') == 1


def test_zero_stamp_is_rejected(make):
    h = make()
    pred, _ = run_with(h, [(0, 200.0)])
    np.testing.assert_array_equal(pred, [1, 2, 4])
    assert rejected(h, 'zero_stamp') == 1


def test_late_packet_is_inserted_and_revised(make):
    h = make()
    y = measurements(owc(), STAMPS)[:, 0]
    order = list(range(8)) + [9, 10, 8] + list(range(11, STAMPS.size))   # t = 11 late
    for i in order:
        h.send(STAMPS[i], y[i])
    N = STAMPS.size
    h.expect(predicted=N - 1, corrected=N - 2, revised_corrected=3, revised_predicted=3,
             revised_mu=3)
    ref = run_filter(owc(), discrete(STAMPS), y[:, None])
    t, x, _ = h.estimates('revised/corrected', 1)
    np.testing.assert_array_equal(t, [10, 11, 12])
    np.testing.assert_allclose(x, ref.x_corr[7:10], rtol=0, atol=1e-9)
    t, x, _ = h.estimates('revised/predicted', 1)
    np.testing.assert_array_equal(t, [11, 12, 16])
    np.testing.assert_allclose(x, ref.x_pred[8:11], rtol=0, atol=1e-9)
    # main topics: each stamp once, in order; after the insertion equal to the offline run
    for topic in ('predicted', 'corrected'):
        t, _, _ = h.estimates(topic, 1)
        assert np.all(np.diff(t) > 0) and 11.0 not in t
    t, x, _ = h.estimates('corrected', 1)
    np.testing.assert_allclose(x[t > 12], ref.x_corr[10:-1], rtol=0, atol=1e-9)
    assert h.node.session.stats.inserted == 1


def test_too_old_packet_is_rejected(make):
    h = make(yaml_parameters('owc_estimator.yaml', history_window=3.0))
    pred, _ = run_with(h, [(1.5, 200.0)], before=(1.0, 2.0, 3.0, 4.0, 5.0), after=6.0)
    np.testing.assert_array_equal(pred, [1, 2, 3, 4, 5, 6])
    assert rejected(h, 'too_old') == 1 and not h.got['revised/predicted']


def test_future_stamp_is_rejected(make):
    h = make(yaml_parameters('owc_estimator.yaml', max_future=10.0))
    now = h.node.get_clock().now().nanoseconds
    for k in range(3):
        h.send(now + k * NS, 200.0)
    h.send(now + 3600 * NS, 200.0)
    h.send(now + 3 * NS, 200.0)
    h.expect(predicted=4)
    assert rejected(h, 'future') == 1
    assert [e.stamp_ns - now for e in h.got['predicted']] == [
        0, NS, 2 * NS, 3 * NS]


def test_backward_jump_reinitialises(make):
    h = make(yaml_parameters('owc_estimator.yaml', max_backward=30.0))
    for t in (100.0, 101.0, 102.0):
        h.send(t, 150.0)
    h.send(5.0, 200.0)              # a looped bag: 97 s back
    h.send(6.0, 200.0)
    h.expect(predicted=5)
    t, x, _ = h.estimates('predicted', 1)
    np.testing.assert_array_equal(t, [100, 101, 102, 5, 6])
    np.testing.assert_array_equal(x[3], owc().x0)          # restarted from x0
    assert h.node.session.stats.resets['backward_jump'] == 1


def test_forward_jump_reinitialises(make):
    h = make(yaml_parameters('owc_estimator.yaml', max_jump=60.0))
    for t in (1.0, 2.0, 500.0):
        h.send(t, 200.0)
    h.expect(predicted=3, corrected=1)
    np.testing.assert_array_equal(h.estimates('predicted', 1)[0], [1, 2, 500])
    np.testing.assert_array_equal(h.estimates('corrected', 1)[0], [1])
    np.testing.assert_array_equal(h.estimates('predicted', 1)[1][-1], owc().x0)
    assert h.node.session.stats.resets['forward_jump'] == 1


def test_clock_jump_back_reinitialises(make):
    h = make(yaml_parameters('owc_estimator.yaml') + [Parameter('use_sim_time', value=True)])
    clock_pub = h.client.create_publisher(Clock, '/clock', 10)
    h.spin_until(lambda: clock_pub.get_subscription_count() > 0, '/clock subscriber')
    clock_pub.publish(Clock(clock=conversions.ns_to_stamp(1000 * NS)))
    h.spin_until(lambda: h.node.get_clock().now().nanoseconds == 1000 * NS, 'sim time')
    for t in (1.0, 2.0):
        h.send(t, 200.0)
    clock_pub.publish(Clock(clock=conversions.ns_to_stamp(10 * NS)))
    h.spin_until(lambda: h.node.session.stats.resets['clock_jump'] == 1, 'the reset')
    assert h.node.session.pending() is None
    h.send(3.0, 200.0)
    h.expect(predicted=3)
    np.testing.assert_array_equal(h.estimates('predicted', 1)[1][-1], owc().x0)


@pytest.mark.parametrize('name, value, reason', [
    ('Q', [1.0, 0.0], 'Q must have 1 entries'),
    ('R', [-100.0], 'positive definite'),
    ('A', [1.0, 2.0], 'n^2 entries'),
    ('P0', [-1.0], 'indefinite'),
    ('transition', 'rk4', 'transition must be one of'),
])
def test_bad_parameter_is_refused_and_filter_keeps_running(make, name, value, reason):
    h = make()
    for t in (1.0, 2.0):
        h.send(t, 200.0)
    result = h.node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful and reason in result.reason
    h.send(3.0, 210.0)
    h.expect(predicted=3)
    ref = run_filter(owc(), discrete([1.0, 2.0, 3.0]), np.array([[200.0], [200.0], [210.0]]))
    np.testing.assert_allclose(h.estimates('predicted', 1)[1], ref.x_pred, rtol=0, atol=1e-9)


def test_negative_rate_is_refused_by_its_range(make):
    h = make()
    result = h.node.set_parameters([Parameter('period', value=-1.0)])[0]
    assert not result.successful
    assert h.node.config.session.period == 1.0


def test_good_parameter_change_is_used(make):
    h = make()
    assert h.node.set_parameters([Parameter('transition', value='exact')])[0].successful
    assert h.node.session.kf.transition == 'exact'
    stamps, power = (1.0, 2.0, 4.0), (200.0, 210.0, 190.0)
    for t, p in zip(stamps, power):
        h.send(t, p)
    h.expect(predicted=3)
    t, x, P = h.estimates('predicted', 1)
    # model (3) sampled exactly, written out: F = e^mu, Q_d = (e^{2 mu} - 1) / 2, R_d = R / mu
    c, d, R = -637.35, 511.97, 100.0
    xs, Ps, want_x, want_P = 0.5435, 0.01, [0.5435], [0.01]
    for k, mu in enumerate(np.diff(stamps)):
        L = Ps * c / (c * c * Ps + R / mu)
        xs, Ps = xs + L * (power[k] - c * xs - d), Ps - L * c * Ps
        xs, Ps = np.exp(mu) * xs, np.exp(2 * mu) * Ps + (np.exp(2 * mu) - 1) / 2
        want_x.append(xs)
        want_P.append(Ps)
    np.testing.assert_array_equal(t, stamps)
    np.testing.assert_allclose(x[:, 0], want_x, rtol=1e-9)
    np.testing.assert_allclose(P[:, 0, 0], want_P, rtol=1e-9)
    # the Euler step (F = 1 + mu, Q_d = mu) would predict far from that: the change was used
    L = want_P[1] * c / (c * c * want_P[1] + R / 2)
    euler = 3 * (want_x[1] + L * (power[1] - c * want_x[1] - d))
    assert abs(x[2, 0] - euler) > 0.1


def test_diagnostics_warn_on_long_gap(make):
    h = make(yaml_parameters('owc_estimator.yaml', max_gap=5.0))
    for t in (1.0, 2.0, 10.0):
        h.send(t, 200.0)
    h.send(10.0, 200.0)                                   # a duplicate, counted
    n = len(h.diagnostics)
    h.node.publish_diagnostics()
    h.spin_until(lambda: len(h.diagnostics) > n, '/diagnostics')
    statuses = conversions.msg_to_diagnostics(h.diagnostics[-1])
    node = h.node.get_name()
    assert sorted(statuses) == sorted(f'{node}: {task}' for task in (
        'input frequency', 'timestamp delay', 'filter health', 'time scale'))
    times, health = statuses[f'{node}: time scale'], statuses[f'{node}: filter health']
    assert times['level'] == conversions.LEVELS['WARN'][0]
    assert times['Gaps'] == '1' and float(times['Longest gap J (s)']) == 8.0
    assert float(times['mu max (s)']) == 8.0
    assert health['Rejected (duplicate)'] == '1' and float(health['Covariance trace']) > 0


def test_best_effort_publisher_is_matched(make):
    h = make(best_effort=True)
    for t in (1.0, 2.0, 3.0):
        h.send(t, 200.0)
    h.expect(predicted=3, corrected=2)


def test_inputs_are_held_and_outputs_equal_the_core(make):
    h = make(yaml_parameters('drogue_estimator.yaml'))
    # best effort publisher: the input subscription matches it as well as a reliable one
    pub = h.client.create_publisher(AccelStamped, 'input', qos_profile_sensor_data)
    h.spin_until(lambda: pub.get_subscription_count() > 0, 'the input subscription')
    rng = np.random.default_rng(6)
    grid = np.arange(0.0, 110.0, 5.0) + 1000.0       # u every 5 s; fixes only at some
    u = rng.standard_normal(grid.size) * 1e-3
    fixes = {t: rng.standard_normal() for t in grid[[1, 2, 3, 19, 20, 21]]}
    for t, uk in zip(grid, u):
        before = h.node.session.stats.inputs_received
        pub.publish(conversions.input_to_msg(int(t * NS), [uk]))
        h.spin_until(lambda: h.node.session.stats.inputs_received > before, 'the input')
        if t in fixes:
            h.send(t, fixes[t])
    # the core: the time-scale filter stepped at every input stamp from the first fix on
    config = h.node.config.session
    kf = config.model.make_filter(config.transition)
    points = grid[1:]
    pred, corr = [], []
    for k, t in enumerate(points[:-1]):
        res = kf.step(points[k + 1] - t, fixes.get(t), [u[k + 1]])
        pred.append(res.x_predicted)
        if t in fixes:
            corr.append(res.x_corrected)
    h.expect(predicted=points.size, corrected=len(fixes) - 1, mu=points.size - 1)
    t, x, _ = h.estimates('predicted', 2)
    np.testing.assert_array_equal(t, points)
    np.testing.assert_allclose(x[1:], pred, rtol=0, atol=1e-9)
    t, x, _ = h.estimates('corrected', 2)
    np.testing.assert_array_equal(t, sorted(fixes)[:-1])
    np.testing.assert_allclose(x, corr, rtol=0, atol=1e-9)
    stats = h.node.session.stats
    assert stats.inputs_accepted == grid.size and stats.accepted == len(fixes)
    assert not stats.rejected


# -- QoS: outputs reliable at depth 10, overridable; the input keeps sensor data ----------

def test_outputs_keep_ten_and_a_qos_override_takes_effect(make):
    h = make(yaml_parameters(
        'owc_estimator.yaml', queue_depth=250,
        **{'qos_overrides./estimate/corrected.publisher.depth': 3,
           'qos_overrides./estimate/corrected.publisher.reliability': 'best_effort'}))
    pubs = h.node.pubs
    assert set(pubs) == {'predicted', 'corrected', 'revised'}      # smoothing off
    assert pubs['predicted'].qos_profile.depth == 10
    assert pubs['predicted'].qos_profile.reliability == ReliabilityPolicy.RELIABLE
    assert pubs['corrected'].qos_profile.depth == 3
    assert pubs['corrected'].qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    # the override is a read-only parameter of the node, as rclpy declares it
    assert h.node.get_parameter('qos_overrides./estimate/corrected.publisher.depth').value == 3
    assert not h.node.set_parameters([Parameter(
        'qos_overrides./estimate/predicted.publisher.depth', value=5)])[0].successful
    assert h.node.sub.qos_profile.depth == 250
    assert h.node.sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    # the best-effort output still reaches a (best-effort matching) subscriber
    for t in (1.0, 2.0, 3.0):
        h.send(t, 200.0)
    h.expect(predicted=3)


def test_a_durability_override_latches_the_output_for_a_late_subscriber(make):
    h = make(yaml_parameters(
        'owc_estimator.yaml',
        **{'qos_overrides./estimate/corrected.publisher.durability': 'transient_local'}))
    pubs = h.node.pubs
    assert pubs['corrected'].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert pubs['predicted'].qos_profile.durability == DurabilityPolicy.VOLATILE
    # nobody subscribes to estimate/corrected while the samples come
    for sub in [s for s in h.client.subscriptions if s.topic_name == '/estimate/corrected']:
        h.client.destroy_subscription(sub)
    h.spin_until(lambda: pubs['corrected'].get_subscription_count() == 0, 'no subscriber')
    for t in (1.0, 2.0, 3.0, 4.0):
        h.send(t, 200.0)
    h.expect(predicted=4)
    # a subscriber that comes afterwards gets the corrected estimates kept (t = 1, 2, 3:
    # the estimate at t_k goes out with sample k + 1)
    late = []
    h.client.create_subscription(
        Float64MultiArray, 'estimate/corrected', late.append,
        QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    h.spin_until(lambda: len(late) >= 3, 'the latched estimates')
    assert [conversions.msg_to_state_estimate(m).stamp_ns for m in late] == [
        k * NS for k in (1, 2, 3)]


# -- fixed-lag smoothing: x(t_j|t_{j+L}) equals the full smoother on that prefix ---------

def smoothed_reference(model, stamps, y, last):
    """rts_smooth (the full RTS smoother) over the points stamps[:last + 1]: (xs, Ps)."""
    mu = np.diff(stamps)[:last + 1]
    return rts_smooth(model.A, model.C, mu, y[:last + 1], Q=model.Q, R=model.R, G=model.G,
                      D=model.D, x0=model.x0, P0=model.P0)


def smoothed_harness(make, lag, **extra):
    h = make(yaml_parameters('owc_estimator.yaml', smoothing_lag=lag, **extra))
    got = []
    h.client.create_subscription(Float64MultiArray, 'estimate/smoothed',
                                 lambda m: got.append(conversions.msg_to_state_estimate(m)),
                                 QoSProfile(depth=1000))
    h.spin_until(lambda: h.node.pubs['smoothed'].get_subscription_count() > 0)
    return h, got


def test_smoothing_lag_publishes_the_fixed_lag_estimate(make):
    lag = 3
    h, got = smoothed_harness(make, lag)
    y = measurements(owc(), STAMPS)
    for t, yi in zip(STAMPS, y[:, 0]):
        h.send(t, yi)
    # the newest point is not stepped yet: N - 1 steps, the last lag of them not yet due
    due = STAMPS.size - 1 - lag
    h.spin_until(lambda: len(got) >= due, 'the smoothed estimates')
    assert [e.stamp_ns / NS for e in got] == STAMPS[:due].tolist()
    assert {e.kind for e in got} == {'smoothed'}
    for j, e in enumerate(got):
        xs, Ps = smoothed_reference(owc(), STAMPS, y, j + lag)
        np.testing.assert_allclose(e.x, xs[j], rtol=0, atol=1e-9)
        np.testing.assert_allclose(e.P, Ps[j], rtol=1e-9, atol=1e-15)
        assert e.mu == STAMPS[j + 1] - STAMPS[j]
    # smoothing used the later measurements: never a larger variance than the filter's
    _, _, P_corr = h.estimates('corrected', 1)
    assert all(e.P[0, 0] <= P_corr[j][0, 0] + 1e-15 for j, e in enumerate(got))


def test_a_late_sample_rebuilds_the_window(make):
    # t = 11 (point 8) comes after t = 12 and 16; lag 2: points 0..6 were out before it
    lag = 2
    h, got = smoothed_harness(make, lag)
    y = measurements(owc(), STAMPS)
    order = list(range(8)) + [9, 10, 8] + list(range(11, STAMPS.size))
    for i in order:
        h.send(STAMPS[i], y[i, 0])
    due = STAMPS.size - 1 - lag
    h.spin_until(lambda: len(got) >= due, 'the smoothed estimates')
    # every point once, in order, the late one included: none skipped, none repeated
    assert [e.stamp_ns / NS for e in got] == STAMPS[:due].tolist()
    without = np.delete(np.arange(STAMPS.size), 8)
    for j, e in enumerate(got):
        if j == 6:      # out before t = 11 came: smoothed on 9, 10 and 12 (no 11)
            xs, _ = smoothed_reference(owc(), STAMPS[without], y[without], 6 + lag)
        else:           # the rest on the run as revised (the late sample in its place)
            xs, _ = smoothed_reference(owc(), STAMPS, y, j + lag)
        np.testing.assert_allclose(e.x, xs[j], rtol=0, atol=1e-9)


def test_a_reset_flushes_the_window(make):
    lag = 3
    h, got = smoothed_harness(make, lag, max_jump=60.0)
    stamps = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    y = measurements(owc(), stamps)
    for t, yi in zip(stamps, y[:, 0]):
        h.send(t, yi)
    h.spin_until(lambda: len(got) >= 2, 'the smoothed estimates')
    h.send(500.0, 200.0)                    # a forward jump: the filter starts anew
    h.spin_until(lambda: len(got) >= 5, 'the flushed window')
    assert [e.stamp_ns / NS for e in got] == [1, 2, 3, 4, 5]
    # the window's points come out smoothed on what it held: steps from 1 .. 5
    xs, _ = smoothed_reference(owc(), np.append(stamps, 7.0), y, 4)
    np.testing.assert_allclose([e.x[0] for e in got[2:]], xs[2:, 0], rtol=0, atol=1e-9)
    assert [e.stamp_ns / NS for e in got].count(5) == 1
    assert h.node.session.stats.resets['forward_jump'] == 1
