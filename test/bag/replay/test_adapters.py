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

"""The adapters: offline replay equals the live nodes; measurements read as rosbags reads them."""

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.serde import SerdeError
from sensor_msgs.msg import TimeReference
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from tskf_ros.bag.message_types import message_class, typestore
from tskf_ros.bag.player import Player
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.adapters import OfflineEstimator, sample_reader
from tskf_ros.bag.replay.loop import replay
from tskf_ros.messages import alignment_interface, estimator_interface
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import (extractor, INPUT_TYPE, INPUT_TYPES,
                                                   load_config)
from tskf_ros.messages.parameters import flat_parameters
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator
from tskf_ros.tools.demo_collector import wait_for

import yaml

from ..helpers import BAGS, CONFIG, SAMPLES, TIMEOUT
from ..test_cdr import damaged, store_messages

BAG = BAGS / 'owc_cai_td_1hz'
PARAMS = CONFIG / 'owc_estimator.yaml'
LED_BAG = BAGS / 'led_alignment'
LED_PARAMS = CONFIG / 'alignment.yaml'
# the live nodes' queues: deeper than a whole bag, so that in one process (delivery within
# the publish call) nothing is dropped however late the executor takes the messages
DEEP = 1000
SENTINEL = 'flush'


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


def sentinel(cls):
    """Return a message of cls marked as the end of a flush (never a node's output)."""
    msg = cls()
    if cls is TimeReference:
        msg.source = SENTINEL
    elif cls is Float64MultiArray:
        msg.layout.dim = [MultiArrayDimension(label=SENTINEL)]
    else:
        msg.header.frame_id = SENTINEL
    return msg


def is_sentinel(msg):
    """Tell a flush sentinel from a node's output."""
    if isinstance(msg, TimeReference):
        return msg.source == SENTINEL
    if isinstance(msg, Float64MultiArray):
        return any(d.label == SENTINEL for d in msg.layout.dim)
    return msg.header.frame_id == SENTINEL


class Flusher:
    """
    Make sure a client took every message a node in the same process has published.

    Per topic a publisher with the node's QoS, in the same process: once the node has
    published everything, a sentinel published after it lands in the client's queue behind
    the node's messages, so when the client has taken the sentinel it has taken them all.
    """

    def __init__(self, node, topics):
        self.pubs = {t: node.create_publisher(cls, t, QoSProfile(depth=10))
                     for t, cls in topics.items()}

    def matched(self):
        """Tell whether every sentinel publisher reaches the client."""
        return all(p.get_subscription_count() > 0 for p in self.pubs.values())

    def flush(self, executor, live):
        """Publish the sentinels; spin until the client has taken them; drop them."""
        for topic, pub in self.pubs.items():
            pub.publish(sentinel(pub.msg_type))
        spin_until(executor, lambda: all(any(is_sentinel(m) for m in live[t])
                                         for t in self.pubs), 'the flush sentinels')
        for topic in self.pubs:
            live[topic][:] = [m for m in live[topic] if not is_sentinel(m)]


def yaml_overrides(path, key='/**/timescale_estimator'):
    """Return the node's parameters in a YAML file as Parameter overrides."""
    section = flat_parameters(yaml.safe_load(path.read_text())[key]['ros__parameters'])
    return [Parameter(k, value=v) for k, v in section.items()]


def offline_estimates(bag):
    """Return {topic: [StateEstimate]} of the offline replay, collected in memory."""
    res = replay(bag, None, params_file=PARAMS, diagnostics=False)
    out = {}
    for topic, _, msg in res.outputs:
        if isinstance(msg, Float64MultiArray):
            out.setdefault(topic, []).append(conversions.msg_to_state_estimate(msg))
    return res, out


def deep_outputs():
    """Return qos_overrides that keep DEEP estimates on every output of the estimator."""
    return [Parameter(f'qos_overrides./{topic}.publisher.depth', value=DEEP)
            for topic in estimator_interface.OUTPUT_TOPICS.values()]


def test_node_defaults_are_the_adapters(ros_context):
    node = TimescaleEstimator(context=ros_context)
    try:
        live = {name: node.get_parameter(name).value for name in node.schema.names}
    finally:
        node.destroy_node()
    mine = estimator_interface.default_parameters()
    assert set(live) == set(mine)
    for key, value in live.items():
        if isinstance(value, (list, tuple, np.ndarray)) or hasattr(value, 'tolist'):
            assert list(value) == list(mine[key]), key
        else:
            assert value == mine[key], key


def test_live_replay_equals_offline_replay(ros_context):
    res, offline = offline_estimates(BAG)
    assert res.samples == 288 and res.statuses == {'accepted': 288}
    est = TimescaleEstimator(context=ros_context, parameter_overrides=yaml_overrides(PARAMS)
                             + [Parameter('use_sim_time', value=True),
                                Parameter('queue_depth', value=DEEP)] + deep_outputs())
    player = Player(BAG, rate=100.0, clock_hz=200.0, topics=['/received_power'],
                    remap={'/received_power': '/measurement'}, context=ros_context)
    client = rclpy.create_node('replay_client', context=ros_context)
    kinds = {t: Float64MultiArray for t in offline}
    live = {t: [] for t in offline}
    for topic, cls in kinds.items():
        client.create_subscription(cls, topic, live[topic].append, QoSProfile(depth=DEEP))
    flusher = Flusher(client, kinds)
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (est, client):
        executor.add_node(node)
    try:
        # two publishers per output topic: the node's and the flusher's
        spin_until(executor, lambda: all(client.count_publishers(t) >= 2 for t in live)
                   and player.pubs['/received_power'].get_subscription_count()
                   and flusher.matched(), 'matching')
        executor.add_node(player)
        # all played and all taken by the estimator: it has published all it ever will
        spin_until(executor, lambda: player.done.done()
                   and est.session.stats.received == res.samples,
                   lambda: f'the estimator to take the {res.samples} samples (player done: '
                   f'{player.done.done()}, published {player.published}, estimator took '
                   f'{est.session.stats.received})')
        sim_now = est.get_clock().now().nanoseconds
        flusher.flush(executor, live)
    finally:
        executor.shutdown()
        for node in (player, est, client):
            node.destroy_node()
    # the estimator ran on the bag's clock (about 1_700_000_300 s at the end of the play),
    # not the wall clock (years away): the player's /clock goes on at 100x after its last
    # message, so a loaded machine's pause moves it by minutes, never by a day
    assert abs(sim_now - 1_700_000_300 * 10**9) < 86_400 * 10**9
    assert est.session.stats.accepted == 288
    assert set(offline) == {'/estimate/predicted', '/estimate/corrected'}
    for topic, expected in offline.items():
        got = live[topic]
        assert len(got) == len(expected), topic
        got = [conversions.msg_to_state_estimate(m) for m in got]
        assert [(g.kind, g.stamp_ns, g.mu) for g in got] == [
            (e.kind, e.stamp_ns, e.mu) for e in expected], topic
        for g, e in zip(got, expected):
            np.testing.assert_allclose(g.x, e.x, rtol=0, atol=1e-12)
            np.testing.assert_allclose(g.P, e.P, rtol=0, atol=1e-12)


def test_alignment_node_defaults_are_the_adapters(ros_context):
    node = Alignment(context=ros_context)
    try:
        live = {name: node.get_parameter(name).value for name in node.schema.names}
    finally:
        node.destroy_node()
    mine = alignment_interface.default_parameters()
    assert set(live) == set(mine)
    for key, value in live.items():
        assert (list(value) if isinstance(value, (list, tuple)) else value) == mine[key], key


@pytest.mark.parametrize('pat', [False, True])
def test_live_alignment_replay_equals_offline_replay(ros_context, pat):
    # pat: the pointing supervisor (config/alignment.yaml has it off), whose state the
    # node latches on pat_state
    config = alignment_interface.load_config(LED_PARAMS, {'pat.enabled': pat})
    res = replay(LED_BAG, None, params_file=config, diagnostics=False, filter='alignment')
    assert res.topic == '/photodiode' and res.samples == 381
    assert any('open loop' in line for line in res.assumptions)
    topics = list(alignment_interface.BAG_OUTPUT_TOPICS.values())
    offline = {t: [m for name, _, m in res.outputs if name == t] for t in topics}
    # estimates only while tracking: from the third sample with the supervisor
    assert [len(v) for v in offline.values()] == ([378, 378, 381] if pat else [381] * 3)
    offline_states = [m.data for t, _, m in res.outputs
                      if t == alignment_interface.BAG_PAT_STATE_TOPIC]
    assert offline_states == (['acquiring', 'tracking'] if pat else ['disabled'])
    node = Alignment(context=ros_context, parameter_overrides=yaml_overrides(
        LED_PARAMS, '/**/alignment') + [Parameter('use_sim_time', value=True),
                                        Parameter('queue_depth', value=DEEP),
                                        Parameter('pat.enabled', value=pat)])
    player = Player(LED_BAG, rate=10.0, clock_hz=200.0, topics=['/photodiode'],
                    remap={'/photodiode': '/intensity'}, context=ros_context)
    client = rclpy.create_node('alignment_client', context=ros_context)
    kinds = {t: Float64MultiArray for t in topics}
    live = {t: [] for t in topics}
    for topic, cls in kinds.items():
        client.create_subscription(cls, topic, live[topic].append, QoSProfile(depth=DEEP))
    # pat_state, latched: the state the node published as it started, then its transitions
    states = []
    client.create_subscription(String, alignment_interface.PAT_STATE_TOPIC,
                               lambda m: states.append(m.data),
                               alignment_interface.pat_state_qos())
    flusher = Flusher(client, kinds)
    executor = SingleThreadedExecutor(context=ros_context)
    for n in (node, client):
        executor.add_node(n)
    try:
        spin_until(executor, lambda: all(client.count_publishers(t) >= 2 for t in topics)
                   and player.pubs['/photodiode'].get_subscription_count()
                   and flusher.matched() and states, 'matching')
        executor.add_node(player)
        spin_until(executor, lambda: player.done.done()
                   and node.session.stats.received == res.samples,
                   lambda: f'the aligner to take the {res.samples} samples (player done: '
                   f'{player.done.done()}, published {player.published}, aligner took '
                   f'{node.session.stats.received})')
        flusher.flush(executor, live)
        spin_until(executor, lambda: len(states) >= len(offline_states),
                   lambda: f'the pat_state messages (got {states})')
        sim_now = node.get_clock().now().nanoseconds
    finally:
        executor.shutdown()
        for n in (player, node, client):
            n.destroy_node()
    assert abs(sim_now - 1_700_000_020 * 10**9) < 5 * 10**9, 'the node ran on the bag clock'
    assert node.session.stats.used == 381 and not node.session.stats.resets
    assert states == offline_states
    for topic in topics:
        got, expected = live[topic], offline[topic]
        assert len(got) == len(expected), topic
        if topic.endswith('commands'):
            np.testing.assert_allclose([m.data for m in got], [m.data for m in expected],
                                       rtol=0, atol=1e-9)
            continue
        got = [conversions.msg_to_state_estimate(m) for m in got]
        expected = [conversions.msg_to_state_estimate(m) for m in expected]
        assert [g.stamp_ns for g in got] == [e.stamp_ns for e in expected], topic
        for g, e in zip(got, expected):
            assert (g.kind, g.mu, g.names) == (e.kind, e.mu, e.names), topic
            np.testing.assert_allclose(g.x, e.x, rtol=0, atol=1e-9)
            np.testing.assert_allclose(g.P, e.P, rtol=0, atol=1e-9)


def test_offline_alignment_reproduces_the_recorded_run_until_a_sample_is_missing():
    """The bag's EKF ran closed loop; open loop the same filter agrees until the first gap."""
    res = replay(LED_BAG, None, params_file=LED_PARAMS, diagnostics=False, filter='alignment')
    recorded, replayed, stamps = {}, [], []
    for topic, _, msg in res.outputs:
        if topic == '/alignment/estimate':
            msg = deserialize_message(msg.data, message_class(msg.msgtype))
            e = conversions.msg_to_alignment_state(msg)      # the node's units
            recorded[e.stamp_ns] = e.x
        elif topic == '/photodiode':
            stamps.append(msg.log_time_ns)
        elif topic == '/estimate/corrected':
            e = conversions.msg_to_alignment_state(msg)
            replayed.append((e.stamp_ns, e.x))
    step = stamps[1] - stamps[0]
    first_gap = next(i for i, (a, b) in enumerate(zip(stamps, stamps[1:])) if b - a > step)
    assert first_gap >= 10
    for stamp, x in replayed[:first_gap + 1]:
        np.testing.assert_allclose(x, recorded[stamp], rtol=0, atol=1e-9)
    stamp, x = replayed[first_gap + 1]
    assert np.abs(x - recorded[stamp]).max() > 1e-3, 'the scan phase moves at a gap'


# -- the measurement (and the input u) as rosbags reads it ---------------------------------

def outcome(read, data, log_ns=123):
    """Return ('ok', the sample with its floats as bit patterns) or ('error',)."""
    try:
        stamp, value, variance = read(data, log_ns)
    except SerdeError:
        return ('error',)
    return ('ok', stamp, np.array([value, variance]).tobytes())


def rosbags_route(msgtype):
    """Return what the replay reads, through rosbags' deserializer alone."""
    store, extract = typestore(), extractor(msgtype)
    return lambda data, log_ns: extract(store.deserialize_cdr(data, msgtype), log_ns)


@pytest.mark.parametrize('msgtype', list(INPUT_TYPES))
@settings(max_examples=60, deadline=None)
@given(data=st.data(), log_ns=st.integers(0, 2 ** 63 - 1))
def test_a_measurement_is_what_rosbags_reads_in_every_form(msgtype, data, log_ns):
    """Canonical little and big endian (rosbags), and rclpy's Fast-CDR: the drawn values."""
    store = typestore()
    msg = data.draw(store_messages(msgtype))
    read = sample_reader(msgtype, extractor(msgtype))
    little = bytes(store.serialize_cdr(msg, msgtype))
    forms = {'little': little,
             'big': bytes(store.serialize_cdr(msg, msgtype, little_endian=False)),
             'rclpy': serialize_message(deserialize_message(little, message_class(msgtype)))}
    kind = INPUT_TYPES[msgtype]
    stamp = (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
             if kind.stamped else log_ns)
    want = ('ok', stamp, np.array([getattr(msg, kind.value), getattr(msg, kind.variance)
                                   if kind.variance else 0.0], dtype=float).tobytes())
    for form, raw in forms.items():
        assert outcome(read, raw, log_ns) == want, form


@settings(max_examples=400, deadline=None)
@given(case=damaged())
def test_damaged_bytes_give_the_outcome_rosbags_gives(case):
    """Values where rosbags gives values (the same), its error where it refuses them."""
    msgtype, raw = case
    read = sample_reader(msgtype, extractor(msgtype))
    assert outcome(read, raw) == outcome(rosbags_route(msgtype), raw)


@pytest.mark.parametrize('name', SAMPLES)
def test_every_measurement_of_the_sample_bags_reads_as_rclpy_and_rosbags_read_it(name):
    reader = BagReader(BAGS / name)
    topics = {t: i.msgtype for t, i in reader.topics.items() if i.msgtype in INPUT_TYPES}
    assert topics, name
    seen = 0
    for raw in reader.messages():
        msgtype = topics.get(raw.topic)
        if msgtype is not None:
            by_rclpy = extractor(msgtype)(deserialize_message(raw.data,
                                                              message_class(msgtype)),
                                          raw.log_time_ns)
            got = outcome(sample_reader(msgtype, extractor(msgtype)), raw.data,
                          raw.log_time_ns)
            assert got == outcome(rosbags_route(msgtype), raw.data, raw.log_time_ns)
            assert got == ('ok', by_rclpy[0], np.array(by_rclpy[1:]).tobytes())
            seen += 1
    assert seen > 0


def test_the_input_u_is_what_rclpy_reads():
    config = load_config(CONFIG / 'drogue_estimator.yaml')
    est = OfflineEstimator(config, 'sensor_msgs/msg/Illuminance')
    inputs = [m for m in BagReader(BAGS / 'drogue').messages() if m.msgtype == INPUT_TYPE]
    assert inputs
    for raw in inputs:
        want = conversions.msg_to_input(deserialize_message(raw.data, message_class(INPUT_TYPE)),
                                        est.session.u.size)
        (stamp, u), _ = est.process_input(raw.data, raw.log_time_ns)
        assert stamp == want[0] and u.tobytes() == want[1].tobytes()
