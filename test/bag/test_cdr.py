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

"""Canonical CDR and the fixed-layout codecs, against rosbags' serializer and deserializer."""

import math
import struct

from hypothesis import given, settings, strategies as st
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.interfaces import Nodetype
from rosbags.rosbag2 import Reader
from rosbags.serde import SerdeError
from sensor_msgs.msg import JointState

from tskf_ros.bag.cdr import EstimateEncoder, fixed_decoder, serialize
from tskf_ros.bag.message_types import message_class, typestore
from tskf_ros.bag.reader import BagReader
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import INPUT_TYPES

from .helpers import BAGS, flatten, mcap_file, NS, SAMPLES, T0

INT_RANGES = {'int8': (-2 ** 7, 2 ** 7 - 1), 'uint8': (0, 2 ** 8 - 1),
              'int16': (-2 ** 15, 2 ** 15 - 1), 'uint16': (0, 2 ** 16 - 1),
              'int32': (-2 ** 31, 2 ** 31 - 1), 'uint32': (0, 2 ** 32 - 1),
              'int64': (-2 ** 63, 2 ** 63 - 1), 'uint64': (0, 2 ** 64 - 1)}
# any text CDR carries (no NUL: it ends a CDR string; no lone surrogates: not UTF-8)
text = st.text(st.characters(blacklist_categories=('Cs',), blacklist_characters='\0'),
               max_size=12)


def bits(value):
    """Return a float's bit pattern (NaN payloads, -0.0 and all), an int as it is."""
    return struct.pack('<d', value) if isinstance(value, float) else value


# -- canonical CDR: what the package writes, every library reads --------------------------

@pytest.mark.parametrize('name', SAMPLES)
def test_every_sample_message_is_canonical_for_rosbags_mcap_ros2_and_rclpy(name):
    """
    Every library decodes every message to the same values: rosbags (strict), mcap_ros2, rclpy.

    Re-serializing a decoded message gives back its bytes exactly (the canonical form).
    """
    store = typestore()
    ours = list(BagReader(BAGS / name).messages())
    with Reader(BAGS / name) as reader:
        theirs = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert sorted((m.topic, m.log_time_ns, m.data) for m in ours) == sorted(theirs)
    with mcap_file(BAGS / name).open('rb') as f:
        decoded = [(ch.topic, m.log_time, d) for _, ch, m, d in
                   make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    assert len(decoded) == len(ours)
    step = max(1, len(ours) // 3000)     # all four bags, a few thousand messages each
    for k in range(0, len(ours), step):
        raw = ours[k]
        by_rosbags = store.deserialize_cdr(raw.data, raw.msgtype)
        by_rclpy = deserialize_message(raw.data, message_class(raw.msgtype))
        want = flatten(by_rclpy)
        assert flatten(by_rosbags) == want, f'{name} message {k}'
        assert decoded[k][:2] == (raw.topic, raw.log_time_ns)
        assert flatten(decoded[k][2]) == want, f'{name} message {k} (mcap_ros2)'
        assert serialize(by_rclpy) == raw.data, f'{name} message {k} is not canonical'
    for raw in ours:     # all of them, strictly: rosbags refuses trailing or missing bytes
        store.deserialize_cdr(raw.data, raw.msgtype)


def test_the_same_message_gives_the_same_bytes():
    msg = conversions.angle_to_msg(T0 + 123, [0.25], ['theta'])
    first = serialize(msg)
    assert all(serialize(msg) == first for _ in range(20))
    # the canonical size, by hand: header (4 + 4 + 4 + 1, padded to 16), name[] (4 + 4 + 6,
    # padded to 16), position[] (4, padded to 8, + 8), velocity[] (4), effort[] (4)
    assert len(first) == 4 + 16 + 16 + 4 + 4 + 8 + 4 + 4 == 60
    padded = serialize_message(msg)          # Fast-CDR: 8 bytes of trailing padding, and
    assert len(padded) == 68                 # its padding bytes are left uninitialised
    assert deserialize_message(padded, JointState) == deserialize_message(first, JointState)


def test_joint_state_padding_is_what_rosbags_refuses():
    """The upstream behaviour the readers must live with (Fast-CDR trailing padding)."""
    padded = serialize_message(JointState(name=['a'], position=[1.0]))
    canonical = serialize(JointState(name=['a'], position=[1.0]))
    assert len(padded) > len(canonical)
    assert deserialize_message(padded, JointState) == deserialize_message(canonical, JointState)
    with pytest.raises(SerdeError):
        typestore().deserialize_cdr(padded, 'sensor_msgs/msg/JointState')


# -- EstimateEncoder against rosbags' serializer -------------------------------------------

def library_bytes(kind, stamp_ns, mu, x, P, names):
    """
    Serialize an estimate with rosbags, from its documented layout (doc/interfaces.md).

    std_msgs/msg/Float64MultiArray: dim[0] = (kind, n + 1, (n + 1) n), dim[1] = (the names
    joined by commas, n, n), data_offset 3, data = [sec, nanosec, mu, x, P row by row].
    """
    store = typestore()
    T = store.types
    sec, nsec = divmod(stamp_ns, NS)
    n = x.size
    dim = T['std_msgs/msg/MultiArrayDimension']
    msg = T['std_msgs/msg/Float64MultiArray'](
        layout=T['std_msgs/msg/MultiArrayLayout'](
            dim=[dim(label=kind, size=n + 1, stride=(n + 1) * n),
                 dim(label=','.join(names), size=n, stride=n)], data_offset=3),
        data=np.concatenate([[float(sec), float(nsec), mu], x, P.reshape(-1)]))
    return bytes(store.serialize_cdr(msg, 'std_msgs/msg/Float64MultiArray'))


def same_values(got, want, msgtype):
    """Compare two serializations field by field as rosbags reads them (NaN equals NaN)."""
    a = flatten(typestore().deserialize_cdr(got, msgtype))
    b = flatten(typestore().deserialize_cdr(want, msgtype))
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], float):
            assert a[key] == b[key] or (math.isnan(a[key]) and math.isnan(b[key])), key
        else:
            assert a[key] == b[key], key


any_float = st.floats(width=64)         # NaN, inf, -0.0, subnormals, the largest
stamps = st.integers(-2 ** 31 * NS, 2 ** 31 * NS - 1)


@settings(max_examples=300, deadline=None)
@given(n=st.integers(1, 6), data=st.data(), kind=st.sampled_from(EstimateEncoder.KINDS),
       stamp=st.integers(0, 2 ** 31 * NS - 1), mu=any_float)
def test_the_fixed_layout_is_what_rosbags_serializes(n, data, kind, stamp, mu):
    x = np.array(data.draw(st.lists(any_float, min_size=n, max_size=n)))
    P = np.array(data.draw(st.lists(any_float, min_size=n * n, max_size=n * n))).reshape(n, n)
    names = data.draw(st.lists(text.filter(lambda t: ',' not in t), min_size=n, max_size=n))
    enc = EstimateEncoder(names)
    want = library_bytes(kind, stamp, mu, x, P, names)
    assert enc.estimate(kind, stamp, mu, x, P) == want      # bit for bit, NaNs included
    # and rclpy reads it back as the message conversions builds
    msg = deserialize_message(want, message_class('std_msgs/msg/Float64MultiArray'))
    got = conversions.msg_to_state_estimate(msg)
    assert (got.kind, got.stamp_ns, got.names) == (kind, stamp, tuple(names))
    np.testing.assert_array_equal(got.x, x)
    np.testing.assert_array_equal(got.P, P)
    assert serialize(conversions.state_estimate_to_msg(kind, stamp, mu, x, P, names)) == want


def test_the_fixed_layout_refuses_what_does_not_fit():
    with pytest.raises(ValueError):
        EstimateEncoder([])


# -- fixed_decoder against rosbags' deserializer -------------------------------------------

def base_values(spec):
    """Return a strategy of any value of a fixed-size base type (floats: all, extremes too)."""
    name = spec[0]
    if name == 'float64':
        return st.floats(width=64)
    if name == 'float32':
        return st.floats(width=32)
    if name == 'string':
        return text
    return st.integers(*INT_RANGES[name])


@st.composite
def store_messages(draw, msgtype):
    """Draw a rosbags message of msgtype with any field values, built from its definition."""
    store = typestore()
    kwargs = {}
    for name, (node, spec) in store.fielddefs[msgtype][1]:
        assert node in (Nodetype.NAME, Nodetype.BASE), (msgtype, name)
        kwargs[name] = (draw(store_messages(spec)) if node == Nodetype.NAME
                        else draw(base_values(spec)))
    return store.types[msgtype](**kwargs)


def wanted(msg, msgtype):
    """Return (stamp ns or None, value, variance or absent) as the replay reads a message."""
    kind = INPUT_TYPES[msgtype]
    stamp = (msg.header.stamp.sec * NS + msg.header.stamp.nanosec) if kind.stamped else None
    fields = [kind.value] + ([kind.variance] if kind.variance else [])
    return (stamp, *(bits(float(getattr(msg, f))) for f in fields))


def decoded(decode, data):
    got = decode(data)
    return None if got is None else (got[0], *(bits(v) for v in got[1:]))


@pytest.mark.parametrize('msgtype', list(INPUT_TYPES))
@settings(max_examples=80, deadline=None)
@given(data=st.data())
def test_the_decoder_reads_what_rosbags_serializes(msgtype, data):
    """Any field values, extremes included; rosbags' LE bytes and rclpy's: the drawn values."""
    store = typestore()
    msg = data.draw(store_messages(msgtype))
    kind = INPUT_TYPES[msgtype]
    decode = fixed_decoder(msgtype, [kind.value] + ([kind.variance] if kind.variance else []))
    little = bytes(store.serialize_cdr(msg, msgtype))
    big = bytes(store.serialize_cdr(msg, msgtype, little_endian=False))
    fast_cdr = serialize_message(deserialize_message(little, message_class(msgtype)))
    assert decoded(decode, little) == wanted(msg, msgtype)
    assert decoded(decode, fast_cdr) == wanted(msg, msgtype)
    assert decode(big) is None                  # rosbags' to read
    assert wanted(store.deserialize_cdr(big, msgtype), msgtype) == wanted(msg, msgtype)


@st.composite
def damaged(draw):
    """Draw a serialized measurement, cut, spliced with garbage, or with bytes overwritten."""
    msgtype = draw(st.sampled_from(sorted(INPUT_TYPES)))
    raw = bytearray(typestore().serialize_cdr(draw(store_messages(msgtype)), msgtype))
    how = draw(st.sampled_from(['cut', 'overwrite', 'length', 'header', 'append', 'random']))
    if how == 'cut':
        raw = raw[:draw(st.integers(0, len(raw)))]
    elif how == 'overwrite':
        for _ in range(draw(st.integers(1, 4))):
            raw[draw(st.integers(0, len(raw) - 1))] = draw(st.integers(0, 255))
    elif how == 'length' and len(raw) >= 16:        # the frame_id's length field
        raw[12:16] = struct.pack('<I', draw(st.integers(0, 2 ** 32 - 1)))
    elif how == 'header':
        raw[:4] = draw(st.binary(min_size=4, max_size=4))
    elif how == 'append':
        raw += draw(st.binary(max_size=12))
    else:
        raw = bytearray(draw(st.binary(max_size=64)))
    return msgtype, bytes(raw)


@settings(max_examples=500, deadline=None)
@given(case=damaged())
def test_damaged_bytes_the_decoder_takes_are_what_rosbags_reads(case):
    """Little endian: the decoder reads what rosbags reads; the rest it leaves to rosbags."""
    msgtype, raw = case
    kind = INPUT_TYPES[msgtype]
    got = decoded(fixed_decoder(msgtype, [kind.value] + ([kind.variance] if kind.variance
                                                         else [])), raw)
    try:
        want = wanted(typestore().deserialize_cdr(raw, msgtype), msgtype)
    except SerdeError:
        assert got is None
        return
    assert got == (want if raw[:2] == b'\x00\x01' else None)
