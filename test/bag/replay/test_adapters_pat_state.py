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

"""The alignment replay's pat_state: the supervisor's transitions as the node publishes them."""

from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Illuminance
from std_msgs.msg import String

from tskf_ros.bag.message_types import typestore
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.loop import replay
from tskf_ros.bag.writer import BagWriter
from tskf_ros.led.alignment_session import AlignmentSession
from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages import conversions

from ..helpers import BAGS, CONFIG, mcap_file, NS, T0

LED_BAG = BAGS / 'led_alignment'
LED_PARAMS = CONFIG / 'alignment.yaml'
PAT = aligner.BAG_PAT_STATE_TOPIC
DT_NS = NS // 20            # the node's dt, 0.05 s


def light_dark_bag(path):
    """
    Write /intensity at 20 Hz: light 0-4 s, dark 4-7 s, light to 12 s, then 2 s back.

    The last 2 s of light are stamped 11 s back (logged on): the supervisor acquires,
    loses, re-acquires and, the aligner restarted, acquires again.
    """
    rng = np.random.default_rng(3)
    with BagWriter(path) as w:
        w.add_topic(aligner.BAG_INPUT_TOPIC, 'sensor_msgs/msg/Illuminance')
        w.add_topic('/other', 'std_msgs/msg/String')      # logged before the first sample
        w.write('/other', T0 - NS, serialize_message(String(data='before')))
        for k in range(240):
            volts = 0.02 * rng.standard_normal() + (0.0 if 80 <= k < 140 else 3.0)
            stamp = T0 + k * DT_NS
            w.write(aligner.BAG_INPUT_TOPIC, stamp, serialize_message(
                conversions.intensity_to_msg(stamp, volts, 0.04)))
        for j in range(40):         # > max_backward (5 s) back: the aligner restarts
            stamp = T0 + NS + j * DT_NS
            w.write(aligner.BAG_INPUT_TOPIC, T0 + 12 * NS + j * DT_NS, serialize_message(
                conversions.intensity_to_msg(stamp, 3.0, 0.04)))
    return path


def stepped(bag, topic, config):
    """
    Return what the live node would publish, stepping an AlignmentSession as it does.

    The bag read by rosbags, each sample decoded by rclpy and msg_to_intensity (the node's
    callback); (log ns, topic) of every output in order, and (log ns, state) on pat_state:
    the start state at the bag's first log time, then each transition after its sample's
    outputs.
    """
    session = AlignmentSession(config.session)
    with Reader(bag) as r:
        raws = list(r.messages())
    first = raws[0][1]
    order = [(first, PAT)] * len(session.pointing.pending)
    states = [(first, t.new) for t in session.take_transitions()]
    for connection, log_ns, data in raws:
        if connection.topic != topic:
            continue
        msg = deserialize_message(data, Illuminance)
        stamp_ns, volts, _ = conversions.msg_to_intensity(msg)
        out = session.add(stamp_ns, volts, now_ns=log_ns)
        order += [(log_ns, aligner.BAG_OUTPUT_TOPICS[key])
                  for key, _ in aligner.outcome_messages(out, config)]
        for t in session.take_transitions():
            order.append((log_ns, PAT))
            states.append((log_ns, t.new))
    return order, states


def outputs_of(res):
    """Return (log ns, topic) of the node's outputs and (log ns, state) of pat_state."""
    node = set(aligner.BAG_OUTPUT_TOPICS.values()) | {PAT}
    order = [(n, t) for t, n, _ in res.outputs if t in node]
    return order, [(n, m.data) for t, n, m in res.outputs if t == PAT]


@pytest.mark.parametrize('bag, topic, params', [
    ('light_dark', aligner.BAG_INPUT_TOPIC, None),                  # the node's defaults
    ('led_alignment', '/photodiode', LED_PARAMS)])                  # Table I, pat on
def test_pat_state_is_the_sessions_transitions_in_order(tmp_path, bag, topic, params):
    path = light_dark_bag(tmp_path / bag) if bag == 'light_dark' else LED_BAG
    config = aligner.load_config(params, {'pat.enabled': True})
    res = replay(path, None, params_file=config, diagnostics=False, filter='alignment')
    assert res.topic == topic
    order, states = outputs_of(res)
    want_order, want_states = stepped(path, topic, config)
    assert states == want_states
    assert order == want_order          # each after its sample's estimates and command
    if bag == 'light_dark':
        assert res.statuses['reset'] == 1
        assert [s for _, s in states] == ['acquiring', 'tracking', 'lost', 'tracking',
                                          'acquiring', 'tracking']
        # the start state comes first, at the first log time (/other's), before any input
        assert res.outputs[0][:2] == (PAT, T0 - NS) and res.outputs[1][0] == '/other'
    else:
        assert [s for _, s in states] == ['acquiring', 'tracking']
    assert res.written[PAT] == len(states)
    # the same messages, in the same places, in the bag written
    replay(path, tmp_path / 'out', params_file=config, filter='alignment')
    written = [(m.topic, m.log_time_ns) for m in BagReader(tmp_path / 'out').messages()
               if m.topic in {PAT, *aligner.BAG_OUTPUT_TOPICS.values()}]
    assert written == [(t, n) for n, t in order]
    with Reader(tmp_path / 'out') as r:
        got = [(t, typestore().deserialize_cdr(data, c.msgtype).data)
               for c, t, data in r.messages() if c.topic == PAT]
    assert got == states


def test_pat_state_in_the_metadata_and_the_summary(tmp_path):
    config = aligner.load_config(LED_PARAMS, {'pat.enabled': True})
    replay(LED_BAG, tmp_path / 'out', params_file=config, filter='alignment')
    with Reader(tmp_path / 'out') as r:             # metadata.yaml, read by rosbags
        pat = r.topics[PAT]
        assert (pat.msgtype, pat.msgcount) == (aligner.PAT_STATE_TYPE, 2)
        offered = pat.connections[0].ext.offered_qos_profiles
        # latched as the node offers it: transient local (1), reliable (1), depth 1
        assert [(q.durability.value, q.reliability.value, q.depth) for q in offered] == \
            [(1, 1, 1)]
    with mcap_file(tmp_path / 'out').open('rb') as f:      # the MCAP summary
        summary = make_reader(f).get_summary()
    channel = next(c for c in summary.channels.values() if c.topic == PAT)
    assert summary.schemas[channel.schema_id].name == aligner.PAT_STATE_TYPE
    assert summary.statistics.channel_message_counts[channel.id] == 2
    # the supervisor's diagnostic task is in /diagnostics as well
    with Reader(tmp_path / 'out') as r:
        names = {s.name for c, _, data in r.messages() if c.topic == '/diagnostics'
                 for s in typestore().deserialize_cdr(data, c.msgtype).status}
    assert 'alignment: pointing' in names


def test_without_the_supervisor_pat_state_holds_the_one_disabled_of_the_start(tmp_path):
    # config/alignment.yaml: pat.enabled false; the node latches 'disabled' as it starts
    # and, without a supervisor, never publishes on pat_state again
    config = aligner.load_config(LED_PARAMS)
    res = replay(LED_BAG, tmp_path / 'out', params_file=config, filter='alignment')
    assert res.written[PAT] == 1
    with Reader(tmp_path / 'out') as r:
        assert (r.topics[PAT].msgtype, r.topics[PAT].msgcount) == (aligner.PAT_STATE_TYPE, 1)
        first = next(iter(r.messages()))
    assert first[0].topic == PAT and first[1] == T0
    assert typestore().deserialize_cdr(first[2], aligner.PAT_STATE_TYPE).data == 'disabled'
    _, want_states = stepped(LED_BAG, '/photodiode', config)
    assert want_states == [(T0, 'disabled')]
