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

"""BagWriter: metadata.yaml and MCAP file as rosbags and mcap read them, atomic, disk full."""

import errno
import os
import zlib

from mcap.reader import make_reader
import pytest
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from tskf_ros.bag import mcap_file as mcap_module
from tskf_ros.bag.message_types import qos_from_rclpy, typestore
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.writer import BagExistsError, BagWriter, DiskFullError
from tskf_ros.messages import conversions

import yaml

from .helpers import make_bag, mcap_file, NS, T0

FULL = 'No space left on device'
# what differs between our metadata.yaml and rosbags' by design
OURS_ONLY = ('relative_file_paths', 'files', 'custom_data', 'ros_distro')


def sample(k):
    """Return (log time, CDR bytes) of power sample k: 200 + k mW, 1 s apart."""
    stamp = T0 + k * NS
    return stamp, serialize_message(conversions.power_to_msg(stamp, 200.0 + k, 4.0))


def metadata(bag):
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def read_all(bag):
    """Return the log times via rosbags (checked equal to mcap's, validating CRCs, and ours)."""
    with Reader(bag) as r:
        theirs = [t for _, t, _ in r.messages()]
    with mcap_file(bag).open('rb') as f:
        library = [m.log_time for _, _, m in make_reader(f, validate_crcs=True).iter_messages()]
    reader = BagReader(bag)
    ours = [m.log_time_ns for m in reader.messages()]
    assert ours == theirs == library
    assert reader.damage is None
    return ours


# -- the files, against rosbags' writer and the mcap package's reader ---------------------

def test_metadata_is_what_rosbags_writes_for_the_same_messages(tmp_path):
    qos = [qos_from_rclpy(qos_profile_sensor_data)]
    with BagWriter(tmp_path / 'ours') as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance', qos=qos)
        w.add_topic('/empty', 'sensor_msgs/msg/Illuminance')
        for k in (0, 3, 1, 4):                   # log times out of order
            w.write('/received_power', *sample(k))
    theirs = Writer(tmp_path / 'theirs', version=9, storage_plugin=StoragePlugin.MCAP)
    theirs.open()
    conn = theirs.add_connection('/received_power', 'sensor_msgs/msg/Illuminance',
                                 typestore=typestore(), offered_qos_profiles=qos)
    theirs.add_connection('/empty', 'sensor_msgs/msg/Illuminance', typestore=typestore())
    for k in (0, 3, 1, 4):
        theirs.write(conn, *sample(k))
    theirs.close()
    ours, want = metadata(tmp_path / 'ours'), metadata(tmp_path / 'theirs')
    assert {k: v for k, v in ours.items() if k not in OURS_ONLY} == \
        {k: v for k, v in want.items() if k not in OURS_ONLY}
    assert ours['files'] == [dict(want['files'][0], path='ours.mcap')]
    assert ours['relative_file_paths'] == ['ours.mcap']
    assert ours['custom_data'] == {'tskf_ros.writer': 'tskf_ros'}
    assert ours['ros_distro'] == 'jazzy'


@pytest.mark.parametrize('compress', [False, True])
def test_the_mcap_file_is_what_the_mcap_package_reads_with_its_crcs(tmp_path, compress):
    with BagWriter(tmp_path / 'bag', compress=compress, chunk_size=500) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        w.add_topic('/other', 'sensor_msgs/msg/Illuminance')
        written = []
        for k in range(40):
            topic = '/other' if k % 3 == 0 else '/received_power'
            w.write(topic, *sample(k))
            written.append((topic, *sample(k)))
    with mcap_file(tmp_path / 'bag').open('rb') as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        got = [(ch.topic, m.log_time, m.data) for _, ch, m in reader.iter_messages()]
        header = reader.get_header()
    assert got == written
    assert header.profile == 'ros2'
    assert summary.statistics.message_count == 40
    assert {summary.channels[c].topic: n
            for c, n in summary.statistics.channel_message_counts.items()} == \
        {'/other': 14, '/received_power': 26}
    assert len(summary.chunk_indexes) > 3
    assert {c.compression for c in summary.chunk_indexes} == {'zstd' if compress else ''}
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
    for channel in summary.channels.values():
        assert channel.message_encoding == 'cdr'
        assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
    assert read_all(tmp_path / 'bag') == [t for _, t, _ in written]


# -- whole or not at all ------------------------------------------------------------------

def test_the_bag_appears_under_its_name_only_when_closed(tmp_path):
    w = BagWriter(tmp_path / 'bag')
    w.open()
    w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
    w.write('/received_power', *sample(0))
    w.flush()
    assert not (tmp_path / 'bag').exists()
    assert w.partial_path.parent.name.startswith('.bag.partial-')
    w.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']
    assert read_all(tmp_path / 'bag') == [T0]
    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / 'other') as w:
            w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
            w.write('/received_power', *sample(0))
            raise RuntimeError('interrupted')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']


def test_overwrite_replaces_only_our_own_bag(tmp_path):
    bag = make_bag(tmp_path / 'bag', range(3))
    with pytest.raises(BagExistsError, match='exists already, not overwriting'):
        BagWriter(bag).open()
    with BagWriter(bag, overwrite=True) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        w.write('/received_power', *sample(7))
    assert read_all(bag) == [T0 + 7 * NS]
    (bag / 'notes.txt').write_text('mine')         # our own bag with an extra file in it
    with pytest.raises(BagExistsError, match='also holds notes.txt'):
        BagWriter(bag, overwrite=True).open()
    (bag / 'notes.txt').unlink()
    meta = bag / 'metadata.yaml'                    # a rosbag2 bag of someone else
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['custom_data'] = None
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagExistsError, match='no tskf_ros.writer in its custom_data'):
        BagWriter(bag, overwrite=True).open()
    victim = tmp_path / 'victim'
    (victim / 'sub').mkdir(parents=True)
    (victim / 'sub' / 'notes.txt').write_text('keep me')
    with pytest.raises(BagExistsError, match='not a bag written by tskf_ros'):
        BagWriter(victim, overwrite=True).open()
    assert (victim / 'sub' / 'notes.txt').read_text() == 'keep me'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'victim']


# -- full disk ----------------------------------------------------------------------------

def install_quota(monkeypatch, limit):
    """Make the MCAP file writes fail with ENOSPC beyond `limit` bytes (a disk that fills)."""
    real = mcap_module.OutputFile.write_some

    def write_some(self, view):
        room = limit - self.pos
        if room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, view[:room])
    monkeypatch.setattr(mcap_module.OutputFile, 'write_some', write_some)


def test_a_full_disk_keeps_what_was_written_as_a_valid_bag(tmp_path, monkeypatch):
    install_quota(monkeypatch, 6000)
    bag = tmp_path / 'full'
    w = BagWriter(bag, chunk_size=100_000)
    w.open()
    w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
    accepted = flushed = 0
    with pytest.raises(DiskFullError) as error:
        for k in range(1000):
            w.write('/received_power', *sample(k))
            accepted += 1
            if accepted % 10 == 0:
                w.flush()               # every 10 messages reach the disk (a chunk each)
                flushed = accepted
    assert 10 <= flushed < accepted <= flushed + 10
    assert str(error.value).startswith(f'{bag}: the disk is full ({FULL}) after ')
    with pytest.raises(DiskFullError):  # and it stays failed
        w.write('/received_power', *sample(0))
    assert w.close() == bag
    assert read_all(bag) == [T0 + k * NS for k in range(flushed)]
    assert w.counts == {'/received_power': flushed}
    meta = metadata(bag)
    assert meta['message_count'] == flushed
    assert meta['custom_data']['tskf_ros.incomplete'] == str(error.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['full']


def test_a_full_disk_while_closing_keeps_every_message(tmp_path, monkeypatch):
    # the summary no longer fits: the data section is kept, sealed without a summary
    with BagWriter(tmp_path / 'probe', chunk_size=100_000) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(30):
            w.write('/received_power', *sample(k))
        w.flush()
        data_end = w.partial_path.joinpath('probe.mcap').stat().st_size
    install_quota(monkeypatch, data_end + 20)
    bag = tmp_path / 'bag'
    w = BagWriter(bag, chunk_size=100_000)
    w.open()
    w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
    for k in range(30):
        w.write('/received_power', *sample(k))
    w.flush()
    assert w.close() == bag
    assert isinstance(w.error, DiskFullError)
    assert read_all(bag) == [T0 + k * NS for k in range(30)]


def test_a_bag_sealed_after_a_full_disk_carries_its_data_section_crc(tmp_path, monkeypatch):
    install_quota(monkeypatch, 6000)
    bag = tmp_path / 'full'
    w = BagWriter(bag, chunk_size=100_000)
    w.open()
    w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
    with pytest.raises(DiskFullError):
        for k in range(1000):
            w.write('/received_power', *sample(k))
            if k % 10 == 9:
                w.flush()
    w.close()
    data = mcap_file(bag).read_bytes()
    at = len(data) - 8 - 29 - 13            # DataEnd, Footer (no summary), magic
    assert data[at] == 0x0F
    stored = int.from_bytes(data[at + 9:at + 13], 'little')
    assert stored == zlib.crc32(data[:at]) != 0
