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

"""A chunk's messages read at once (message_block, cdr.fixed_block_decoder) against one by one."""

import struct

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np

from tskf_ros.bag.cdr import fixed_block_decoder, fixed_decoder
from tskf_ros.bag.message_types import typestore
from tskf_ros.bag.reader import BagReader, MessageBlock, RawMessage
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages.estimator_interface import INPUT_TYPES

from .helpers import mcap_file, NS, T0

ILLUMINANCE = 'sensor_msgs/msg/Illuminance'


def illuminance(stamp_ns, value, variance, frame=b'power_meter'):
    """Return the CDR of an Illuminance (as rosbags and rclpy write it)."""
    sec, nsec = divmod(stamp_ns, NS)
    head = struct.pack('<4siII', b'\0\1\0\0', sec, nsec, len(frame) + 1) + frame + b'\0'
    return head + b'\0' * (-(len(head) - 4) % 8) + struct.pack('<dd', value, variance)


def flat(items):
    """Return the RawMessages of a message_blocks() walk, blocks expanded."""
    out = []
    for item in items:
        out += list(item.messages()) if isinstance(item, MessageBlock) else [item]
    return out


frames = st.sampled_from([b'power_meter', b'pm', b'x' * 9, b'power_meter_2'])
samples = st.lists(st.tuples(
    st.integers(0, 2 ** 31 - 1), st.integers(0, NS - 1),
    st.floats(allow_nan=False), st.floats(allow_nan=False), st.sampled_from(['/a', '/b'])),
    min_size=0, max_size=40)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(samples=samples, frame=frames, mixed_frames=st.booleans(), compress=st.booleans(),
       chunk_size=st.sampled_from([None, 300, 2000]))
def test_the_blocks_are_the_messages_one_by_one(tmp_path_factory, samples, frame,
                                                mixed_frames, compress, chunk_size):
    path = tmp_path_factory.mktemp('bag') / 'bag'
    kwargs = {} if chunk_size is None else {'chunk_size': chunk_size}
    with BagWriter(path, compress=compress, **kwargs) as w:
        w.add_topic('/a', ILLUMINANCE)
        w.add_topic('/b', ILLUMINANCE)
        for k, (sec, nsec, v, var, topic) in enumerate(samples):
            f = frame + b'z' * (k % 3) if mixed_frames else frame
            w.write(topic, T0 + k, illuminance(sec * NS + nsec, v, var, f))
    reader = BagReader(path)
    one = list(reader.messages())
    assert all(isinstance(m, RawMessage) for m in one)
    assert flat(reader.message_blocks()) == one
    assert flat(reader.message_blocks(['/a'])) == [m for m in one if m.topic == '/a']
    decode = fixed_decoder(ILLUMINANCE, ['illuminance', 'variance'])
    block = fixed_block_decoder(ILLUMINANCE, ['illuminance', 'variance'])
    store = typestore()
    for item in reader.message_blocks():
        if isinstance(item, MessageBlock):
            got = block(item.payloads)
            rows = [decode(m.data) for m in item.messages()]
            if got is None:
                continue
            assert [tuple(r) for r in zip(*(c.tolist() for c in got))] == rows
            for m, stamp in zip(item.messages(), got[0].tolist()):
                msg = store.deserialize_cdr(m.data, ILLUMINANCE)
                assert stamp == msg.header.stamp.sec * NS + msg.header.stamp.nanosec


@given(rows=st.lists(st.binary(min_size=40, max_size=40), min_size=1, max_size=8),
       msgtype=st.sampled_from(sorted(INPUT_TYPES)))
def test_the_block_decoder_is_the_row_decoder_or_none(rows, msgtype):
    kind = INPUT_TYPES[msgtype]
    fields = [kind.value] + ([kind.variance] if kind.variance else [])
    block = fixed_block_decoder(msgtype, fields)
    one = fixed_decoder(msgtype, fields)
    for data in (rows, [b'\0\1\0\0' + r[4:] for r in rows]):
        got = block(np.frombuffer(b''.join(data), dtype=np.uint8).reshape(len(data), -1))
        if got is not None:
            expected = [one(r) for r in data]
            assert all(e is not None for e in expected)
            columns = [[None] * len(data) if c is None else c.tolist() for c in got]
            assert [tuple(r) for r in zip(*columns)] == expected


def test_a_truncated_file_is_one_line_of_damage(tmp_path):
    path = tmp_path / 'bag'
    with BagWriter(path, chunk_size=500) as w:
        w.add_topic('/a', ILLUMINANCE)
        for k in range(50):
            w.write('/a', T0 + k, illuminance(T0 + k, float(k), 1.0))
    mcap = mcap_file(path)
    mcap.write_bytes(mcap.read_bytes()[:1500])
    reader = BagReader(path)
    got = flat(reader.message_blocks())
    assert 0 < len(got) < 50 and [m.log_time_ns for m in got] == [T0 + k for k in range(len(got))]
    assert 'truncated' in str(reader.damage) and '\n' not in str(reader.damage)


def test_one_topic_of_one_frame_comes_in_blocks_compressed_or_not(tmp_path):
    for compress in (False, True):
        path = tmp_path / f'bag_{compress}'
        with BagWriter(path, compress=compress, chunk_size=2000) as w:
            w.add_topic('/a', ILLUMINANCE)
            for k in range(200):
                w.write('/a', T0 + k, illuminance(T0 + 7 * k, k / 3, 2.0))
        reader = BagReader(path)
        items = list(reader.message_blocks())
        assert sum(len(i) for i in items if isinstance(i, MessageBlock)) > 150
        assert flat(items) == list(reader.messages())
