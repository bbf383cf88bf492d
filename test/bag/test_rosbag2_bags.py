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

"""Bags rosbag2 itself wrote (its test resources): read whole, played, reindexed as rosbag2."""

from pathlib import Path
import shutil
import sqlite3

from mcap.reader import make_reader
import pytest
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader
from std_msgs.msg import String

from tskf_ros.bag import reindex
from tskf_ros.bag.player import Player
from tskf_ros.bag.reader import BagReader

import yaml

ROSBAG2 = Path(__file__).resolve().parent.parent / 'data' / 'rosbag2'
SQLITE3 = ('talker', 'convert_a', 'convert_b')


def stored(db3):
    """Return [(topic, type, timestamp, bytes)] of a .db3 file in log time order (sqlite3)."""
    with sqlite3.connect(f'file:{db3}?immutable=1', uri=True) as db:
        return [(t, m, int(s), bytes(d)) for t, m, s, d in db.execute(
            'SELECT topics.name, topics.type, messages.timestamp, messages.data FROM messages '
            'JOIN topics ON messages.topic_id = topics.id ORDER BY messages.timestamp, '
            'messages.id')]


@pytest.mark.parametrize('name', SQLITE3)
def test_sqlite3_bags_of_rosbag2_are_read_whole(name):
    """Every stored message, as the .db3 holds it, and the counts of metadata.yaml."""
    bag = ROSBAG2 / 'sqlite3' / name
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    reader = BagReader(bag)
    got = [(m.topic, m.msgtype, m.log_time_ns, m.data) for m in reader.messages()]
    assert reader.damage is None
    (db3,) = bag.glob('*.db3')
    assert sorted(got) == sorted(stored(db3))
    assert [m[2] for m in got] == sorted(m[2] for m in got)
    assert len(got) == meta['message_count'] > 0
    for entry in meta['topics_with_message_count']:
        topic = entry['topic_metadata']['name']
        assert sum(m[0] == topic for m in got) == entry['message_count']


def test_rosbags_directory_reader_reads_them_as_empty():
    """The cause, kept visible: rosbags pairs topics by the whole QoS string (0 messages)."""
    with Reader(ROSBAG2 / 'sqlite3' / 'talker') as r:
        assert r.message_count == 20
        assert sum(1 for _ in r.messages()) == 0


def test_the_talker_reads_the_same_from_sqlite3_and_mcap():
    texts = {}
    for storage in ('sqlite3', 'mcap'):
        reader = BagReader(ROSBAG2 / storage / 'talker')
        texts[storage] = [deserialize_message(m.data, String).data
                          for m in reader.messages(['/topic'])]
    assert texts['sqlite3'] == texts['mcap'] == [f'Hello, world! {k}' for k in range(10)]


def test_a_sqlite3_bag_of_rosbag2_plays(ros_context):
    player = Player(ROSBAG2 / 'sqlite3' / 'talker', topics=['/topic'], context=ros_context,
                    node_name='player_sqlite3')
    try:
        while not player.done.done():
            player._tick()
        assert player.published == {'/topic': 10}
    finally:
        player.destroy_node()


def mcap_counts(files):
    """Return topic -> messages of MCAP files, read with the mcap package alone."""
    counts = {}
    for path in files:
        with path.open('rb') as f:
            for _, channel, _ in make_reader(f).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return counts


def test_reindex_of_rosbag2s_multiple_files_test_bag(tmp_path, capsys):
    """rosbag2's reindex test case: the files in number order, one metadata.yaml for all."""
    bag = tmp_path / 'multiple_files'
    shutil.copytree(ROSBAG2 / 'mcap' / 'reindex_test_bags' / 'multiple_files', bag)
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    assert reindex.main([str(bag)]) == 0
    names = [f'multiple_files_{k}.mcap' for k in range(3)]
    counts = mcap_counts(bag / n for n in names)
    total = sum(counts.values())
    assert capsys.readouterr().out == f'reindex: wrote {bag} ({total} messages)\n'
    assert {p.name: p.read_bytes() for p in bag.glob('*.mcap')} == before  # closed: untouched
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == names
    assert [f['path'] for f in info['files']] == names
    assert [f['message_count'] for f in info['files']] == \
        [sum(mcap_counts([bag / n]).values()) for n in names]
    with Reader(bag) as r:
        assert r.message_count == total
        stamps = [t for _, t, _ in r.messages()]
        assert len(stamps) == total
        assert {t: i.msgcount for t, i in r.topics.items()} == counts
    assert info['starting_time']['nanoseconds_since_epoch'] == stamps[0]
    assert info['duration']['nanoseconds'] == stamps[-1] - stamps[0]
    reader = BagReader(bag)
    assert sum(1 for _ in reader.messages()) == total and reader.damage is None


def test_reindex_takes_the_files_in_number_order_not_name_order(tmp_path):
    bag = tmp_path / 'b'
    src = ROSBAG2 / 'mcap' / 'reindex_test_bags' / 'multiple_files'
    bag.mkdir()
    for k, new in ((0, 'b_2.mcap'), (1, 'b_10.mcap'), (2, 'b_11.mcap')):
        shutil.copy(src / f'multiple_files_{k}.mcap', bag / new)
    assert reindex.main([str(bag)]) == 0
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == ['b_2.mcap', 'b_10.mcap', 'b_11.mcap']


def test_reindex_refuses_several_files_of_unknown_order_in_one_line(tmp_path, capsys):
    bag = tmp_path / 'b'
    bag.mkdir()
    src = ROSBAG2 / 'mcap' / 'reindex_test_bags' / 'multiple_files'
    shutil.copy(src / 'multiple_files_0.mcap', bag / 'first.mcap')
    shutil.copy(src / 'multiple_files_1.mcap', bag / 'second.mcap')
    assert reindex.main([str(bag)]) == 1
    assert capsys.readouterr().err == (
        f'reindex: error: {bag}: 2 MCAP files not named NAME_<n>.mcap: their order is '
        'unknown\n')
    assert not (bag / 'metadata.yaml').exists()
