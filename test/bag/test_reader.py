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

"""BagReader: damage is BagError or reported damage (Hypothesis), CRCs, confinement."""

from pathlib import Path
import shutil
import struct
import tempfile

from hypothesis import given, HealthCheck, settings, strategies as st
from mcap.reader import make_reader
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Illuminance

from tskf_ros.bag.reader import BagError, BagReader, MetadataError
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions

import yaml

from .helpers import BAGS, make_bag, mcap_file, NS, T0

N = 24
SETTINGS = settings(derandomize=True, max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


def _make(path, compress):
    with BagWriter(path, compress=compress, chunk_size=400) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        w.add_topic('/other', 'sensor_msgs/msg/Illuminance')
        for k in range(N):
            stamp = T0 + k * NS
            w.write('/received_power' if k % 3 else '/other', stamp, serialize_message(
                conversions.power_to_msg(stamp, 200.0 + k, 4.0)))
    return path


@pytest.fixture(scope='module')
def pristine():
    """Return {compress: (mcap bytes, metadata.yaml text)} of two small valid bags."""
    top = Path(tempfile.mkdtemp(prefix='tskf_props_'))
    try:
        out = {}
        for compress in (False, True):
            bag = _make(top / f'b{int(compress)}', compress)
            out[compress] = ((bag / f'{bag.name}.mcap').read_bytes(),
                             (bag / 'metadata.yaml').read_text())
        yield out
    finally:
        shutil.rmtree(top)


def read_everything(path):
    """Open and read a bag; return (messages, damage), or raise BagError."""
    reader = BagReader(path)
    msgs = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    return msgs, reader.damage


def check(path, expected):
    """
    Whatever the damage: a one-line BagError, or the original messages up to the damage.

    The messages read are always the first ones of the original bag, byte for byte (the
    chunk and data CRCs leave no silent change); fewer than all means damage is reported.
    """
    try:
        msgs, damage = read_everything(path)
    except BagError as exc:
        assert str(exc) and '\n' not in str(exc)
        return
    assert msgs == expected[:len(msgs)]
    if damage is None:
        assert len(msgs) == len(expected)
    else:
        assert damage.messages_before == len(msgs)
        assert '\n' not in str(damage)


def write_bag(tmp_path, name, mcap_bytes, meta_text):
    bag = tmp_path / name
    bag.mkdir()
    (bag / f'{name}.mcap').write_bytes(mcap_bytes)
    (bag / 'metadata.yaml').write_text(meta_text)
    return bag


def expected_messages():
    out = []
    for k in range(N):
        stamp = T0 + k * NS
        out.append(('/received_power' if k % 3 else '/other', stamp, serialize_message(
            conversions.power_to_msg(stamp, 200.0 + k, 4.0))))
    return out


flips = st.lists(st.tuples(st.integers(min_value=0), st.integers(min_value=0, max_value=7)),
                 min_size=1, max_size=4)


@SETTINGS
@given(compress=st.booleans(), flips=flips, bare=st.booleans())
def test_flipped_bits_raise_bag_error_or_report_damage(pristine, tmp_path_factory,
                                                       compress, flips, bare):
    data, meta = pristine[compress]
    damaged = bytearray(data)
    for pos, bit in flips:
        damaged[pos % len(damaged)] ^= 1 << bit
    tmp = tmp_path_factory.mktemp('flip')
    bag = write_bag(tmp, 'b', bytes(damaged), meta.replace(f'b{int(compress)}', 'b'))
    check(bag / 'b.mcap' if bare else bag, expected_messages())


@SETTINGS
@given(compress=st.booleans(), cut=st.integers(min_value=0), bare=st.booleans())
def test_truncations_keep_a_prefix(pristine, tmp_path_factory, compress, cut, bare):
    data, meta = pristine[compress]
    tmp = tmp_path_factory.mktemp('cut')
    bag = write_bag(tmp, 'b', data[:cut % (len(data) + 1)],
                    meta.replace(f'b{int(compress)}', 'b'))
    check(bag / 'b.mcap' if bare else bag, expected_messages())


@SETTINGS
@given(text=st.text(max_size=200), keep=st.integers(min_value=0))
def test_damaged_metadata_is_a_bag_error(pristine, tmp_path_factory, text, keep):
    data, meta = pristine[False]
    meta = meta.replace('b0', 'b')
    tmp = tmp_path_factory.mktemp('meta')
    bag = write_bag(tmp, 'b', data, meta[:keep % (len(meta) + 1)] + text)
    check(bag, expected_messages())


# -- CRCs: a flipped bit is damage, never a value -----------------------------------------

def power_bag(path, n, chunk_size):
    """Write n Illuminance samples of 200 + k mW, 1 s apart; return the path."""
    with BagWriter(path, chunk_size=chunk_size) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(n):
            stamp = T0 + k * NS
            w.write('/received_power', stamp, serialize_message(
                conversions.power_to_msg(stamp, 200.0 + k, 4.0)))
    return path


def flip_exponent(mcap, value):
    """Flip an exponent bit of the float64 `value` in the file: value * 2**256."""
    data = bytearray(mcap.read_bytes())
    pos = data.index(struct.pack('<d', value))
    data[pos + 7] ^= 0x10
    assert struct.unpack_from('<d', data, pos)[0] == pytest.approx(value * 2.0 ** 256)
    mcap.write_bytes(bytes(data))
    return pos


def corrupt_bag(path, n=30, flip=206.0, chunk_size=600):
    """Return a bag of power_bag whose value `flip` has an exponent bit flipped."""
    power_bag(path, n, chunk_size)
    flip_exponent(mcap_file(path), flip)
    return path


def test_a_flipped_bit_is_damage_not_a_value(tmp_path):
    reader = BagReader(corrupt_bag(tmp_path / 'bag'))
    got = [conversions.msg_to_power(deserialize_message(m.data, Illuminance))[1]
           for m in reader.messages()]
    assert reader.damage is not None
    assert 'corrupt a chunk (chunk CRC mismatch)' in str(reader.damage)
    assert 0 < len(got) <= 6 and max(got) < 206.0
    assert got == [200.0 + k for k in range(len(got))]


def test_a_flipped_bit_outside_the_chunks_fails_the_data_crc(tmp_path):
    power_bag(tmp_path / 'bag', 5, 768 * 1024)
    mcap = mcap_file(tmp_path / 'bag')
    data = bytearray(mcap.read_bytes())
    index = data.index(bytes([0x07]), 8)         # the message index after the chunk
    while data[index + 9:index + 11] != b'\x01\x00':
        index = data.index(bytes([0x07]), index + 1)
    data[index + 20] ^= 0x01                       # a timestamp in that index
    mcap.write_bytes(bytes(data))
    reader = BagReader(tmp_path / 'bag')
    assert len(list(reader.messages())) == 5
    assert 'data section CRC mismatch' in str(reader.damage)


def flip_in_third_chunk(src, dst):
    """Copy a bag and flip one byte in the middle of its third chunk's data."""
    shutil.copytree(src, dst)
    path = mcap_file(dst)
    data = bytearray(path.read_bytes())
    pos, chunks = 8, []
    while data[pos] != 0x0F:                 # top-level records up to DataEnd
        length = struct.unpack_from('<Q', data, pos + 1)[0]
        if data[pos] == 0x06:
            chunks.append((pos, length))
        pos += 9 + length
    assert len(chunks) >= 4
    start, length = chunks[2]
    data[start + 9 + length // 2] ^= 0x40
    path.write_bytes(bytes(data))
    return dst


def test_a_byte_flipped_in_a_sample_bag_is_damage_and_the_chunks_before_are_read(tmp_path):
    bag = flip_in_third_chunk(BAGS / 'owc_ge_1khz', tmp_path / 'bag')
    pristine = list(BagReader(BAGS / 'owc_ge_1khz').messages())
    reader = BagReader(bag)
    got = list(reader.messages())
    assert reader.damage is not None and 'CRC mismatch' in str(reader.damage)
    assert 0 < len(got) == reader.damage.messages_before < len(pristine)
    assert got == pristine[:len(got)]


# -- what a bag is: its metadata against its messages, confined storage files -------------

@pytest.mark.parametrize('name', ['owc_cai_td_1hz', 'owc_ge_1khz', 'led_alignment',
                                  'led_pan_tilt', 'drogue'])
def test_the_messages_are_what_rosbags_and_mcap_read_and_the_metadata_counts(name):
    reader = BagReader(BAGS / name)
    ours = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    assert reader.damage is None
    with Reader(BAGS / name) as r:
        assert ours == [(c.topic, t, bytes(d)) for c, t, d in r.messages()]
    with mcap_file(BAGS / name).open('rb') as f:
        assert ours == [(ch.topic, m.log_time, m.data)
                        for _, ch, m in make_reader(f, validate_crcs=True).iter_messages()]
    counts = {}
    for topic, _, _ in ours:
        counts[topic] = counts.get(topic, 0) + 1
    assert counts == {t: i.count for t, i in reader.topics.items()}


def test_metadata_cannot_point_outside_the_bag(tmp_path):
    outside = make_bag(tmp_path / 'outside', range(5))
    bag = make_bag(tmp_path / 'deep' / 'bag', range(3))
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    for name in ('../../outside/outside.mcap', str(outside / 'outside.mcap'), '.'):
        doc['rosbag2_bagfile_information']['relative_file_paths'] = [name]
        meta.write_text(yaml.safe_dump(doc))
        with pytest.raises(MetadataError, match='is outside the bag directory; not reading'):
            BagReader(bag)


def test_a_storage_file_symlinked_outside_the_bag_is_refused(tmp_path):
    shutil.copytree(BAGS / 'owc_cai_td_1hz', tmp_path / 'outside')
    bag = tmp_path / 'bag'
    shutil.copytree(BAGS / 'owc_cai_td_1hz', bag)
    name = mcap_file(bag).name
    (bag / name).unlink()
    (bag / name).symlink_to(tmp_path / 'outside' / name)
    with pytest.raises(MetadataError, match='outside the bag directory') as info:
        BagReader(bag)
    assert '\n' not in str(info.value)
