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

"""reindex: a crashed recording (SIGKILL, power loss) becomes a bag rosbags and mcap read."""

import os
import zlib

from mcap.reader import make_reader
from mcap.records import Channel, DataEnd
from mcap.stream_reader import StreamReader
from rosbags.rosbag2 import Reader

from tskf_ros.bag import reindex
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay import cli
from tskf_ros.bag.writer import BagWriter

from .helpers import NS, one_line, T0
from .test_writer import read_all, sample


def crashed_recording(tmp_path, n_flushed, n_unflushed, name='rec'):
    """Return the .partial directory as a SIGKILL after n_flushed + n_unflushed leaves it."""
    w = BagWriter(tmp_path / name, chunk_size=100_000)
    w.open()
    w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
    for k in range(n_flushed + n_unflushed):
        w.write('/received_power', *sample(k))
        if k + 1 == n_flushed:
            w.flush()
    partial = w.partial_path.parent
    snapshot = tmp_path / 'crash' / partial.name
    snapshot.parent.mkdir(exist_ok=True)
    os.replace(partial, snapshot)       # what the disk holds; the process is gone
    w.abort()                           # (its directory is gone already)
    mcap = snapshot / name / f'{name}.mcap'
    with mcap.open('ab') as f:          # a chunk cut short by the kill
        f.write(bytes([0x06]) + (5000).to_bytes(8, 'little') + b'\0' * 100)
    return snapshot


def test_reindex_turns_a_crashed_recording_into_a_bag(tmp_path, capsys):
    partial = crashed_recording(tmp_path, 40, 7)
    assert not (partial / 'rec' / 'metadata.yaml').exists()
    assert reindex.main([str(partial), '-o', str(tmp_path / 'rec')]) == 0
    assert capsys.readouterr().out == f'reindex: wrote {tmp_path / "rec"} (40 messages)\n'
    assert read_all(tmp_path / 'rec') == [T0 + k * NS for k in range(40)]
    with Reader(tmp_path / 'rec') as r:
        assert r.message_count == 40
        assert r.topics['/received_power'].msgtype == 'sensor_msgs/msg/Illuminance'
    assert not partial.exists()
    assert cli.main([str(tmp_path / 'rec'), str(tmp_path / 'est'), '-q']) == 0


def test_reindex_next_to_the_partial_directory_and_in_place(tmp_path, capsys):
    partial = crashed_recording(tmp_path, 12, 3, name='run')
    target = partial.parent / 'run'
    assert reindex.main([str(partial)]) == 0
    assert read_all(target) == [T0 + k * NS for k in range(12)]
    # a bag whose metadata.yaml is stale: rewritten in place, the file untouched
    before = (target / 'run.mcap').read_bytes()
    meta = target / 'metadata.yaml'
    meta.write_text(meta.read_text().replace('message_count: 12', 'message_count: 999'))
    assert reindex.main([str(target)]) == 0
    assert (target / 'run.mcap').read_bytes() == before
    with Reader(target) as r:
        assert r.message_count == 12
    # an empty recording: nothing to reindex, one line, nothing touched
    empty = tmp_path / '.e.partial-x' / 'e'
    empty.mkdir(parents=True)
    (empty / 'e.mcap').write_bytes(b'')
    capsys.readouterr()
    assert reindex.main([str(empty.parent)]) == 1
    assert capsys.readouterr().err == \
        f'reindex: error: {empty / "e.mcap"}: empty file (0 bytes): nothing was recorded\n'


def test_reindex_refuses_a_missing_path_in_one_line(tmp_path, capsys):
    assert reindex.main([str(tmp_path / 'nope')]) == 1
    one_line(capsys.readouterr().err, 'reindex: error: ', 'no such directory')
    assert list(tmp_path.iterdir()) == []


def data_end_crc(mcap):
    """Return (DataEnd's data_section_crc, the CRC-32 of every byte before DataEnd)."""
    data = mcap.read_bytes()
    # a sealed file ends: DataEnd (9 + 4 bytes), Footer (9 + 20), magic (8)
    at = len(data) - 8 - 29 - 13
    assert data[at] == 0x0F                 # the DataEnd opcode
    return int.from_bytes(data[at + 9:at + 13], 'little'), zlib.crc32(data[:at])


def test_a_sealed_recording_carries_its_data_section_crc(tmp_path):
    partial = crashed_recording(tmp_path, 25, 4)
    assert reindex.main([str(partial), '-o', str(tmp_path / 'rec')]) == 0
    mcap = tmp_path / 'rec' / 'rec.mcap'
    stored, computed = data_end_crc(mcap)
    assert stored == computed != 0
    with mcap.open('rb') as f:              # the mcap package checks it and reads them all
        records = list(StreamReader(f, validate_crcs=True).records)
    assert sum(isinstance(r, DataEnd) for r in records) == 1
    assert read_all(tmp_path / 'rec') == [T0 + k * NS for k in range(25)]


def test_a_topic_without_messages_whose_channel_is_in_the_summary_only_is_kept(tmp_path):
    bag = tmp_path / 'bag'
    with BagWriter(bag) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(5):
            w.write('/received_power', *sample(k))
        w.flush()
        # a topic subscribed at the end, which never published: its Channel goes into a
        # chunk without messages, which the mcap Writer does not write
        w.add_topic('/silent', 'std_msgs/msg/Float64')
    mcap = bag / 'bag.mcap'
    with mcap.open('rb') as f:
        data_channels = set()
        for record in StreamReader(f, emit_chunks=False).records:
            if isinstance(record, DataEnd):
                break
            if isinstance(record, Channel):
                data_channels.add(record.topic)
        f.seek(0)
        summary = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert data_channels == {'/received_power'} and summary == {'/received_power', '/silent'}
    (bag / 'metadata.yaml').unlink()
    assert reindex.main([str(bag)]) == 0
    with Reader(bag) as r:
        assert {t: (i.msgtype, i.msgcount) for t, i in r.topics.items()} == {
            '/received_power': ('sensor_msgs/msg/Illuminance', 5),
            '/silent': ('std_msgs/msg/Float64', 0)}
    assert set(BagReader(mcap).topics) == {'/received_power', '/silent'}
