"""The node's reused output messages are what rosbags serializes from x, P; unwatched: unsent."""

from pathlib import Path
import time

from bag.test_cdr import library_bytes, same_values
from geometry_msgs.msg import TwistWithCovarianceStamped
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState

from tskf_ros.bag.cdr import serialize
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import load_config, OutcomeMessages
from tskf_ros.nodes.node_base import make_executor
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator
from tskf_ros.owc.session import Estimate, EstimatorSession, Jump, Outcome

CONFIG = Path(__file__).resolve().parents[2] / 'config'
T0 = 1_700_000_000 * NS
TIMEOUT = 60.0      # s: only a bound on waiting for DDS; no assertion depends on timing
finite = st.floats(allow_nan=False, allow_infinity=False)
# a stamp the session passes on: [0, 2^31) s in integer nanoseconds
stamps = st.integers(min_value=0, max_value=2**31 * NS - 1)


@st.composite
def outcomes(draw, n):
    """Draw an Outcome of n-state estimates (repeated kinds, as revisions come) and jumps."""
    estimates = [Estimate(draw(st.sampled_from(['predicted', 'corrected'])), draw(stamps),
                          np.array(draw(st.lists(finite, min_size=n, max_size=n))),
                          np.array(draw(st.lists(finite, min_size=n * n, max_size=n * n)))
                          .reshape(n, n), draw(st.booleans()))
                 for _ in range(draw(st.integers(0, 4)))]
    jumps = [Jump(draw(stamps), draw(stamps), draw(st.booleans()))
             for _ in range(draw(st.integers(0, 3)))]
    return Outcome('accepted', estimates=estimates, jumps=jumps)


@st.composite
def configs_and_outcomes(draw):
    """Draw a node config with n states (1..6), a frame_id, and outcomes of that size."""
    n = draw(st.integers(1, 6))
    names = draw(st.lists(st.text('abcxyz_', min_size=1, max_size=12), min_size=n,
                          max_size=n))
    frame = draw(st.text('abc/_', max_size=20))
    eye = np.eye(n).ravel().tolist()
    config = load_config(overrides={
        'A': [0.0] * (n * n), 'C': [1.0] + [0.0] * (n - 1), 'D': [], 'G': eye, 'Q': eye,
        'R': [1.0], 'x0': [0.0] * n, 'P0': eye, 'state_names': names,
        'frame_id': frame, 'nonpositive_is_gap': False})
    return config, draw(st.lists(outcomes(n), min_size=1, max_size=3))


def expected_bytes(out, config):
    """Return {(kind, revised): [bytes]} of an outcome, serialized by rosbags from x, P, mu."""
    names = config.session.model.state_names
    want = {}
    for e in out.estimates:
        twist, states, _ = library_bytes(e.stamp_ns, np.asarray(e.x), np.asarray(e.P),
                                         config.frame_id, names, 0)
        want.setdefault((e.kind, e.revised), []).append(twist)
        want.setdefault((e.kind + '_states', e.revised), []).append(states)
    for j in out.jumps:
        want.setdefault(('mu', j.revised), []).append(
            library_bytes(j.stamp_ns, np.zeros(1), np.zeros((1, 1)), '', [''], j.sigma_ns)[2])
    return want


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(configs_and_outcomes())
def test_the_reused_messages_are_what_rosbags_serializes_from_the_estimates(case):
    config, outs = case
    reused = OutcomeMessages(config)
    for out in outs:
        got = {}
        for key, msg in reused.messages(out):
            # serialized before the next message is filled, as the node publishes it; in
            # canonical CDR (rosbags): rclpy's Fast-CDR leaves padding bytes uninitialised,
            # so the same message need not give the same bytes twice through it
            got.setdefault(key, []).append(serialize(msg))
        want = expected_bytes(out, config)
        assert got.keys() == want.keys()
        for key, items in got.items():
            assert len(items) == len(want[key]), key
            for a, b in zip(items, want[key]):
                if a != b:     # only sqrt(max(-0.0, 0)): the sign of that zero is free
                    same_values(a, b, 'sensor_msgs/msg/JointState')
                    assert key[0].endswith('_states'), key


def test_each_field_is_what_the_estimate_says():
    # independent of outcome_messages: the fields read back against x, P and the stamps
    config = load_config(CONFIG / 'reference_estimator.yaml', {'frame_id': 'rig'})
    x, P = np.array([0.5, -1.25]), np.array([[4.0, 0.3], [0.3, 0.25]])
    t = 1_700_000_000 * NS + 123
    out = Outcome('accepted', estimates=[Estimate('corrected', t, x, P)],
                  jumps=[Jump(t, t + 5 * NS // 1000)])
    msgs = {}
    for key, msg in OutcomeMessages(config).messages(out):
        msgs[key] = msg
    twist = msgs[('corrected', False)]
    assert twist.header.stamp.sec == 1_700_000_000 and twist.header.stamp.nanosec == 123
    assert twist.header.frame_id == 'rig'
    assert (twist.twist.twist.linear.x, twist.twist.twist.linear.y) == (0.5, -1.25)
    assert (twist.twist.twist.linear.z, twist.twist.twist.angular.x) == (0.0, 0.0)
    cov = np.asarray(twist.twist.covariance).reshape(6, 6)
    np.testing.assert_array_equal(cov[:2, :2], P)
    assert not cov[2:].any() and not cov[:, 2:].any()
    states = msgs[('corrected_states', False)]
    assert list(states.name) == ['position', 'velocity'] and states.header.frame_id == 'rig'
    assert list(states.position) == [0.5, -1.25] and list(states.velocity) == [2.0, 0.5]
    assert conversions.msg_to_jump(msgs[('mu', False)]) == (t, 0.005)


def test_a_smaller_state_leaves_nothing_of_a_larger_one():
    msg = TwistWithCovarianceStamped()
    conversions.fill_estimate_msg(msg, NS, np.arange(1.0, 4.0), np.ones((3, 3)))
    conversions.fill_estimate_msg(msg, 2 * NS, [7.0], [[2.0]])
    assert serialize(msg) == library_bytes(2 * NS, np.array([7.0]), np.array([[2.0]]), '',
                                           ['x'], 0)[0]
    states = JointState(name=['a', 'b', 'c'], position=[1.0, 2.0, 3.0], velocity=[1.0] * 3)
    conversions.fill_joint_state(states, NS, [7.0], [[4.0]])
    assert list(states.position) == [7.0] and list(states.velocity) == [2.0]


def test_a_late_sample_publishes_every_revision():
    # a late sample revises several points: one reused message carries each in turn
    config = load_config(CONFIG / 'owc_estimator.yaml')
    session = EstimatorSession(config.session)
    for k in (1, 2, 3, 5, 6):
        session.add(k * NS, 200.0 + k)
    out = session.add(4 * NS, 190.0)
    assert out.status == 'inserted'
    revised = [(key, conversions.msg_to_estimate(msg, 1)[0])
               for key, msg in OutcomeMessages(config).messages(out)
               if key == ('corrected', True)]
    want = [e.stamp_ns for e in out.estimates if (e.kind, e.revised) == ('corrected', True)]
    assert len(want) >= 2 and [s for _, s in revised] == want


def test_the_node_publishes_only_what_somebody_subscribes_to(ros_context, executor_kind):
    node = TimescaleEstimator(context=ros_context)
    client = rclpy.create_node('only_predicted', context=ros_context)
    predicted = []
    client.create_subscription(TwistWithCovarianceStamped, 'estimate/predicted',
                               predicted.append, QoSProfile(depth=100))
    published = {key: 0 for key in node.pubs}
    for key, pub in node.pubs.items():
        def counting(msg, key=key, publish=pub.publish):
            published[key] += 1
            publish(msg)
        pub.publish = counting
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(node)
    executor.add_node(client)
    deadline = time.monotonic() + TIMEOUT
    try:
        while node.pubs[('predicted', False)].get_subscription_count() < 1:
            assert time.monotonic() < deadline, 'our subscription never matched'
            executor.spin_once(timeout_sec=0.05)
        for k in (1, 2, 3):
            node._on_measurement(conversions.power_to_msg(k * NS, 165.0))
        while len(predicted) < 3:
            assert time.monotonic() < deadline, 'the predicted estimates never came'
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        node.destroy_node()
        client.destroy_node()
    assert published == {key: 3 if key == ('predicted', False) else 0 for key in node.pubs}
    assert [conversions.stamp_to_ns(m.header.stamp) for m in predicted] == [NS, 2 * NS, 3 * NS]


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


def test_load_config_has_the_new_defaults():
    cfg = load_config()
    assert cfg.session.gate == 10.0 and cfg.session.state_limit == 1e9
    assert cfg.session.measurement_range == ()
