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
The Foxglove bridge: a ROS topic reaches a Foxglove WebSocket client as CDR with its schema.

The client is the `websockets` library speaking the Foxglove WebSocket protocol (subprotocol
foxglove.sdk.v1, which foxglove-sdk's server speaks; foxglove.websocket.v1 is refused); the
payloads are checked with rclpy's deserializer, and the ros2msg schemas by decoding the CDR
with mcap_ros2 (Foxglove's own ros2msg parser and CDR reader) and against rosbags' message
definitions (a peer implementation of the same encoding).
"""

import array
from contextlib import contextmanager
import json
import re
import struct
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_check_compatible, QoSCompatibility,
                       QoSProfile, ReliabilityPolicy)
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import Illuminance, JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from tskf_ros.bag.message_types import message_class
from tskf_ros.messages import alignment_interface, estimator_interface
from tskf_ros.messages.conversions import STATES_TYPE
from tskf_ros.messages.qos import matching_qos
from tskf_ros.tools.foxglove_bridge import BridgeError, FoxgloveBridge, main, SUBPROTOCOL
from tskf_ros.tools.message_definitions import DefinitionError, ros2msg_definition, SEPARATOR

from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

TIMEOUT = 60.0    # s: the longest wait for one condition (a loaded machine)
SLICE = 0.2       # s: one wait for a frame, after which the test publishes again
MESSAGE_DATA = 0x01    # opcode of a server's binary message frame
MSG_LINE = re.compile(r'^MSG: (\S+)$', re.M)
# every message type the package's nodes publish or take
PACKAGE_TYPES = sorted({
    *estimator_interface.INPUT_TYPES, alignment_interface.ESTIMATE_TYPE, STATES_TYPE,
    estimator_interface.ESTIMATE_TYPE, estimator_interface.INPUT_TYPE,
    estimator_interface.DIAGNOSTICS_TYPE, alignment_interface.COMMAND_TYPE,
    alignment_interface.PAT_STATE_TYPE})


def assert_same(ros_msg, decoded) -> None:
    """Assert that a decoded message has the fields and values of an rclpy message."""
    for name in ros_msg.get_fields_and_field_types():
        mine, theirs = getattr(ros_msg, name), getattr(decoded, name)
        if hasattr(mine, 'get_fields_and_field_types'):
            assert_same(mine, theirs)
        elif isinstance(mine, (list, tuple, array.array, np.ndarray)):
            assert len(mine) == len(theirs), name
            for a, b in zip(mine, theirs):
                if hasattr(a, 'get_fields_and_field_types'):
                    assert_same(a, b)
                else:
                    assert a == b, name
        elif isinstance(mine, bytes):          # a `byte` field: one byte in rclpy
            assert mine == (theirs if isinstance(theirs, bytes) else bytes([theirs])), name
        else:
            assert mine == theirs, name


def decode(msgtype: str, definition: str, payload: bytes):
    """Decode CDR bytes with mcap_ros2, given the ros2msg definition of their type."""
    schema = Schema(id=1, name=msgtype, encoding='ros2msg', data=definition.encode())
    return DecoderFactory().decoder_for('cdr', schema)(payload)


def sample(msgtype: str):
    """Return a message of the type with fields set (nested arrays where the type has them)."""
    if msgtype == 'diagnostic_msgs/msg/DiagnosticArray':
        msg = DiagnosticArray(status=[DiagnosticStatus(
            level=DiagnosticStatus.WARN, name='timescale_estimator: filter',
            message='gap', hardware_id='pm100',
            values=[KeyValue(key='J', value='2.5'), KeyValue(key='n', value='7')])])
    elif msgtype == STATES_TYPE:
        msg = JointState(name=['x1', 'x2'], position=[0.25, -1.5], velocity=[0.125, 2.0])
    elif msgtype == alignment_interface.COMMAND_TYPE:
        msg = Float64MultiArray(data=[0.5, -0.25])
        msg.layout.dim = [MultiArrayDimension(label='joint', size=2, stride=2)]
    elif msgtype == alignment_interface.PAT_STATE_TYPE:
        msg = message_class(msgtype)(data='tracking')
    else:
        msg = message_class(msgtype)()
        kind = estimator_interface.INPUT_TYPES.get(msgtype)
        if kind is not None:
            setattr(msg, kind.value, 0.4375)
            if kind.variance:
                setattr(msg, kind.variance, 0.015625)
    if hasattr(msg, 'header'):
        msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345_000_000
        msg.header.frame_id = 'power_meter'
    return msg


@pytest.mark.parametrize('msgtype', PACKAGE_TYPES)
def test_the_schema_decodes_the_cdr_of_every_package_type(msgtype):
    definition = ros2msg_definition(msgtype)
    msg = sample(msgtype)
    assert_same(msg, decode(msgtype, definition, serialize_message(msg)))
    # the same dependent types as rosbags' definition of the type (the order may differ)
    theirs, _ = get_typestore(Stores.ROS2_JAZZY).generate_msgdef(msgtype, ros_version=2)
    names = {name.replace('/msg/', '/') for name in MSG_LINE.findall(definition)}
    assert names == set(MSG_LINE.findall(theirs))
    assert definition.count(SEPARATOR) == len(names)


def test_the_subscription_qos_matches_every_publisher_and_is_the_strongest_that_does():
    profiles = [QoSProfile(depth=10, reliability=r, durability=d)
                for r in (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT)
                for d in (DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL)]
    for mask in range(1, 2 ** len(profiles)):
        offered = [p for i, p in enumerate(profiles) if mask >> i & 1]
        mine = matching_qos(offered, history=HistoryPolicy.KEEP_LAST, depth=5)
        # rclpy's compatibility check: every publisher matches (a WARNING is about the
        # system-default liveliness of both sides, not a mismatch)
        assert all(qos_check_compatible(p, mine)[0] != QoSCompatibility.ERROR
                   for p in offered)
        # and no stronger profile would: each stronger policy fails one publisher
        for stronger in ({'reliability': ReliabilityPolicy.RELIABLE},
                         {'durability': DurabilityPolicy.TRANSIENT_LOCAL}):
            other = QoSProfile(**{'depth': 5, 'reliability': mine.reliability,
                                  'durability': mine.durability, **stronger})
            if (other.reliability, other.durability) != (mine.reliability, mine.durability):
                assert any(qos_check_compatible(p, other)[0] == QoSCompatibility.ERROR
                           for p in offered)


def test_a_type_without_a_definition_is_one_clear_error():
    for name, says in (('no_such_msgs/msg/Thing', 'no_such_msgs is not installed'),
                       ('not a type', 'is not a message type name')):
        with pytest.raises(DefinitionError, match=says) as info:
            ros2msg_definition(name)
        assert '\n' not in str(info.value)


def frames(ws, deadline: float):
    """Yield each frame the server sends, or None after SLICE without one, until deadline."""
    while time.monotonic() < deadline:
        try:
            yield ws.recv(timeout=SLICE)
        except TimeoutError:
            yield None


def ops(frame, op: str) -> list:
    """Return the JSON operation of a text frame as a one-item list if it is `op`."""
    if isinstance(frame, str):
        message = json.loads(frame)
        if message['op'] == op:
            return [message]
    return []


@contextmanager
def spinning(context, *nodes, ready=lambda: True):
    """
    Spin nodes on an executor of their context in a thread while the block runs.

    Yield an Event set once `ready()` is true (checked after each spin, in the thread).
    """
    executor = SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    stop, is_ready = threading.Event(), threading.Event()

    def spin():
        while not stop.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.05)
            if not is_ready.is_set() and ready():
                is_ready.set()

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield is_ready
    finally:
        stop.set()
        thread.join()
        executor.shutdown()


def test_a_published_message_reaches_a_foxglove_client(ros_context):
    topic = '/foxglove_bridge_test/received_power'
    bridge = FoxgloveBridge(context=ros_context, parameter_overrides=[
        Parameter('port', value=0), Parameter('topics', value=[topic]),
        Parameter('discovery_period', value=0.05)])
    talker = rclpy.create_node('talker', context=ros_context)
    publisher = talker.create_publisher(Illuminance, topic, 10)
    # the publisher goes in the executor's thread (entities are destroyed where they spin)
    unpublish = talker.create_guard_condition(lambda: talker.destroy_publisher(publisher))
    msg = sample('sensor_msgs/msg/Illuminance')
    advertised = []
    try:
        with spinning(ros_context, bridge, talker,
                      ready=lambda: topic in bridge.bridged) as served:
            # the client connects once the channel exists: foxglove-sdk 0.30.3 may refuse a
            # subscription to a channel made while the client's handshake is under way
            # ('unknown channel'; doc/design/foxglove.md)
            assert served.wait(TIMEOUT), f'the bridge did not serve {topic} in {TIMEOUT} s'
            with connect(f'ws://127.0.0.1:{bridge.port}', subprotocols=[SUBPROTOCOL],
                         open_timeout=TIMEOUT) as ws:
                assert ws.subprotocol == SUBPROTOCOL
                channel, payload, gone = exchange(ws, topic, publisher, msg, advertised,
                                                  unpublish.trigger)
        assert (channel['encoding'], channel['schemaEncoding'], channel['schemaName']) \
            == ('cdr', 'ros2msg', 'sensor_msgs/msg/Illuminance')
        assert channel['schema'] == ros2msg_definition('sensor_msgs/msg/Illuminance')
        assert deserialize_message(payload, Illuminance) == msg
        assert_same(msg, decode(channel['schemaName'], channel['schema'], payload))
        # the publisher went: the channel was unadvertised
        assert channel['id'] in gone
        # only the topic asked for was served (not /rosout, /parameter_events)
        assert {c['topic'] for c in advertised} == {topic}
    finally:
        talker.destroy_node()
        bridge.destroy_node()


def exchange(ws, topic: str, publisher, msg, advertised: list, unpublish) -> tuple:
    """
    Wait for topic's channel, subscribe, publish msg until a message frame comes back.

    Then have the publisher destroyed (`unpublish()`) and wait for the channel to be
    unadvertised. Return the channel, the payload of the frame and the unadvertised channel
    ids; every advertised channel is appended to `advertised`.
    """
    deadline = time.monotonic() + TIMEOUT
    channel = None
    for frame in frames(ws, deadline):
        for message in ops(frame, 'advertise'):
            advertised += message['channels']
        channel = next((c for c in advertised if c['topic'] == topic), None)
        if channel is not None:
            break
    assert channel is not None, f'{topic} was not advertised in {TIMEOUT} s'

    ws.send(json.dumps({'op': 'subscribe',
                        'subscriptions': [{'id': 7, 'channelId': channel['id']}]}))
    payload = None
    for frame in frames(ws, deadline):
        if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
            subscription, _ = struct.unpack_from('<IQ', frame, 1)
            assert subscription == 7
            payload = frame[1 + 4 + 8:]
            break
        publisher.publish(msg)     # again until the subscription has matched
    assert payload is not None, f'no message frame in {TIMEOUT} s'

    unpublish()
    gone = []
    for frame in frames(ws, time.monotonic() + TIMEOUT):
        for message in ops(frame, 'advertise'):
            advertised += message['channels']
        gone += [i for m in ops(frame, 'unadvertise') for i in m['channelIds']]
        if channel['id'] in gone:
            break
    return channel, payload, gone


def test_a_client_offering_only_the_old_subprotocol_name_is_refused(ros_context):
    bridge = FoxgloveBridge(context=ros_context,
                            parameter_overrides=[Parameter('port', value=0)])
    try:
        with pytest.raises(InvalidStatus) as info:
            connect(f'ws://127.0.0.1:{bridge.port}', subprotocols=['foxglove.websocket.v1'],
                    open_timeout=TIMEOUT)
        assert info.value.response.status_code == 400
    finally:
        bridge.destroy_node()


def test_a_port_in_use_is_one_line_and_exit_1(ros_context, capsys):
    first = FoxgloveBridge(context=ros_context,
                           parameter_overrides=[Parameter('port', value=0)])
    try:
        with pytest.raises(BridgeError, match=f'cannot serve on 127.0.0.1:{first.port}'):
            FoxgloveBridge(context=ros_context,
                           parameter_overrides=[Parameter('port', value=first.port)])
        with pytest.raises(SystemExit) as info:
            main(['foxglove_bridge', '--ros-args', '-p', f'port:={first.port}'])
        assert info.value.code == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith('foxglove_bridge: cannot start: cannot serve on') \
            and '\n' not in err, err
    finally:
        first.destroy_node()


@pytest.mark.parametrize('depth', [0, 100_001, 4611686018427387904, 2 ** 63 - 1])
def test_a_depth_out_of_range_is_one_line_and_exit_1(depth, capsys):
    # refused at start, not when the first topic is served (rmw's QoS takes no 2**62)
    with pytest.raises(SystemExit) as info:
        main(['foxglove_bridge', '--ros-args', '-p', f'depth:={depth}', '-p', 'port:=0'])
    assert info.value.code == 1
    err = capsys.readouterr().err.strip()
    assert err == ('foxglove_bridge: cannot start: port must be in 0..65535 and depth in '
                   f'1..100000, got port 0, depth {depth}'), err
