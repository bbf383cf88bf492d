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

"""The node's reused estimate messages are what rosbags serializes from x, P; unwatched: unsent."""

from pathlib import Path
import time

from bag.test_cdr import library_bytes, store_messages
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from tskf_ros.bag.cdr import serialize
from tskf_ros.bag.message_types import message_class, typestore
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import (extractor, INPUT_TYPES, load_config,
                                                   outcome_messages, OutcomeMessages,
                                                   output_qos, OUTPUT_TOPICS, raw_reader)
from tskf_ros.nodes.node_runner import make_executor
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


def step_of(e, jumps):
    """Return mu (s) of the step an estimate comes from: into a predicted, out of a corrected."""
    mu = 0.0
    for j in jumps:         # the last jump that matches, as a later step overwrites
        if (j.sigma_ns if e.kind == 'predicted' else j.stamp_ns) == e.stamp_ns:
            mu = (j.sigma_ns - j.stamp_ns) / NS
    return mu


def expected_bytes(out, config):
    """Return {output: [bytes]} of an outcome, serialized by rosbags from x, P, mu."""
    names = config.session.model.state_names
    want = {}
    for e in out.estimates:
        topic = 'revised' if e.revised else e.kind
        want.setdefault(topic, []).append(library_bytes(
            e.kind, e.stamp_ns, step_of(e, out.jumps), np.asarray(e.x), np.asarray(e.P),
            names))
    return want


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(configs_and_outcomes())
def test_the_reused_messages_are_what_rosbags_serializes_from_the_estimates(case):
    config, outs = case
    reused = OutcomeMessages(config)
    for out in outs:
        got = {}
        for key, msg in reused.messages(out):
            # serialized before the next message is filled, as the node publishes it
            got.setdefault(key, []).append(serialize(msg))
        assert got == expected_bytes(out, config)
        assert {key: [serialize(m) for _, m in outcome_messages(out, config) if _ == key]
                for key in got} == got
        # what the node publishes: the same bytes, written without filling the messages
        written = {}
        for key, data in reused.serialized(out):
            written.setdefault(key, []).append(data)
        assert written == got


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(configs_and_outcomes(), stamps, finite, st.data())
def test_a_smoothed_estimate_serialized_is_its_message_serialized(case, stamp_ns, mu, data):
    config = case[0]
    n = len(config.session.model.state_names)
    x = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))
    P = np.array(data.draw(st.lists(finite, min_size=n * n, max_size=n * n))).reshape(n, n)
    reused = OutcomeMessages(config)
    assert reused.smoothed_serialized(stamp_ns, mu, x, P) == library_bytes(
        'smoothed', stamp_ns, mu, x, P, config.session.model.state_names)
    # a transposed (not C-contiguous) P is written row by row, as the message holds it
    assert reused.smoothed_serialized(stamp_ns, mu, x, P.T) == serialize(
        reused.smoothed(stamp_ns, mu, x, P.T))


def test_each_field_is_what_the_estimate_says():
    # independent of outcome_messages: the fields read back against x, P and the stamps
    config = load_config(CONFIG / 'reference_estimator.yaml', {'frame_id': 'rig'})
    x, P = np.array([0.5, -1.25]), np.array([[4.0, 0.3], [0.3, 0.25]])
    t = 1_700_000_000 * NS + 123
    out = Outcome('accepted', estimates=[Estimate('corrected', t, x, P),
                                         Estimate('predicted', t + 5 * NS // 1000, x, P)],
                  jumps=[Jump(t, t + 5 * NS // 1000)])
    msgs = {}
    for key, msg in OutcomeMessages(config).messages(out):
        msgs[key] = list(msg.data), [(d.label, d.size, d.stride) for d in msg.layout.dim], \
            msg.layout.data_offset
    # data = [sec, nanosec, mu, x, P]; dim: rows = mean then covariance, columns = states
    assert msgs['corrected'] == ([1_700_000_000.0, 123.0, 0.005, 0.5, -1.25, 4.0, 0.3, 0.3,
                                  0.25], [('corrected', 3, 6), ('position,velocity', 2, 2)],
                                 3)
    assert msgs['predicted'][0][:3] == [1_700_000_000.0, 5_000_123.0, 0.005]
    assert msgs['predicted'][1][0] == ('predicted', 3, 6)
    # the generic reading of the layout: array(i, j) = data[offset + stride[1] i + j]
    data, dims, offset = msgs['corrected']
    n = dims[1][1]
    array = np.array(data[offset:]).reshape(dims[0][1], n)
    np.testing.assert_array_equal(array[0], x)
    np.testing.assert_array_equal(array[1:], P)


def test_the_prior_at_a_first_point_has_mu_zero():
    config = load_config(CONFIG / 'owc_estimator.yaml')
    out = EstimatorSession(config.session).add(NS, 200.0)
    (key, msg), = outcome_messages(out, config)
    e = conversions.msg_to_state_estimate(msg)
    assert key == 'predicted' and (e.kind, e.stamp_ns, e.mu, e.names) == (
        'predicted', NS, 0.0, ('theta',))


def test_an_estimate_of_another_layout_is_refused():
    msg = conversions.state_estimate_to_msg('corrected', NS, 1.0, [1.0, 2.0], np.eye(2),
                                            ['a', 'b'])
    short = Float64MultiArray(layout=msg.layout, data=list(msg.data)[:-1])
    with pytest.raises(ValueError, match='8 entries for 2 states'):
        conversions.msg_to_state_estimate(short)
    flat = Float64MultiArray(layout=msg.layout, data=msg.data)
    flat.layout.dim = [MultiArrayDimension(label='x', size=9, stride=9)]
    with pytest.raises(ValueError, match='2 dimensions'):
        conversions.msg_to_state_estimate(flat)


def test_a_late_sample_publishes_every_revision_on_one_topic():
    # a late sample revises several points: each on estimate/revised, its kind in the layout
    config = load_config(CONFIG / 'owc_estimator.yaml')
    session = EstimatorSession(config.session)
    for k in (1, 2, 3, 5, 6):
        session.add(k * NS, 200.0 + k)
    out = session.add(4 * NS, 190.0)
    assert out.status == 'inserted'
    revised = [conversions.msg_to_state_estimate(msg)
               for key, msg in OutcomeMessages(config).messages(out) if key == 'revised']
    want = [(e.kind, e.stamp_ns) for e in out.estimates if e.revised]
    assert len(want) >= 4 and [(e.kind, e.stamp_ns) for e in revised] == want
    assert {'predicted', 'corrected'} == {kind for kind, _ in want}


def test_the_outputs_are_at_most_five_topics_with_diagnostics():
    assert len(OUTPUT_TOPICS) + 1 <= 5
    qos = output_qos(load_config())
    assert qos.depth == 10 and qos.reliability == ReliabilityPolicy.RELIABLE


def test_the_node_publishes_only_what_somebody_subscribes_to(ros_context, executor_kind):
    node = TimescaleEstimator(context=ros_context)
    client = rclpy.create_node('only_predicted', context=ros_context)
    predicted = []
    client.create_subscription(Float64MultiArray, 'estimate/predicted',
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
        while node.pubs['predicted'].get_subscription_count() < 1:
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
    assert published == {key: 3 if key == 'predicted' else 0 for key in node.pubs}
    assert [conversions.msg_to_state_estimate(m).stamp_ns for m in predicted] == [
        NS, 2 * NS, 3 * NS]


def test_load_config_has_the_new_defaults():
    cfg = load_config()
    assert cfg.session.gate == 10.0 and cfg.session.state_limit == 1e9
    assert cfg.session.measurement_range == ()


@pytest.mark.parametrize('msgtype', list(INPUT_TYPES))
@settings(max_examples=60, deadline=None)
@given(data=st.data(), log_ns=st.integers(0, 2 ** 63 - 1))
def test_the_nodes_raw_reader_gives_what_rclpy_deserializes(msgtype, data, log_ns):
    """
    The node's raw measurement: extractor of rclpy's deserialize_message, bit for bit.

    rclpy's own bytes (Fast-CDR) and rosbags' canonical little endian, read from the fixed
    layout, and big endian, which the layout leaves to deserialize_message.
    """
    store, cls = typestore(), message_class(msgtype)
    msg = data.draw(store_messages(msgtype))
    little = bytes(store.serialize_cdr(msg, msgtype))
    forms = {'little': little,
             'big': bytes(store.serialize_cdr(msg, msgtype, little_endian=False)),
             'rclpy': serialize_message(deserialize_message(little, cls))}
    read, extract = raw_reader(msgtype), extractor(msgtype)
    for form, raw in forms.items():
        want = extract(deserialize_message(raw, cls), log_ns)
        got = read(raw, log_ns)
        assert type(got[0]) is int and got[0] == want[0], form
        assert np.array(got[1:]).tobytes() == np.array(want[1:]).tobytes(), form
