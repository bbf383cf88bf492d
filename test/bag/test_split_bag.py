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

"""A bag split into files (record -b/-d): crashes, a full disk, overwrite, the smallest limit."""

import errno
import json
import os
import subprocess
import sys

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Illuminance

from tskf_ros.bag import mcap_file, reindex
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.split_bag import SplitBagWriter
from tskf_ros.bag.writer import BagExistsError, DiskFullError
from tskf_ros.messages import conversions

import yaml

from .helpers import NS, T0

TOPIC = '/received_power'


def sample(k):
    """Return message k: log time T0 + k s, the value k."""
    return T0 + k * NS, serialize_message(conversions.power_to_msg(T0 + k * NS, float(k), 1.0))


def values(bag):
    """Return the values of a bag's messages in storage order, and the reader's damage."""
    reader = BagReader(bag)
    got = [deserialize_message(m.data, Illuminance).illuminance for m in reader.messages()]
    return got, reader.damage


def metadata(bag):
    """Return a bag's rosbag2_bagfile_information."""
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def open_split(path, **kwargs):
    """Open a SplitBagWriter with the one topic."""
    w = SplitBagWriter(path, **kwargs)
    w.open()
    w.add_topic(TOPIC, 'sensor_msgs/msg/Illuminance')
    return w


def test_a_limit_of_one_byte_gives_one_message_per_file(tmp_path):
    w = open_split(tmp_path / 'one', max_bytes=1)
    for k in range(5):
        w.write(TOPIC, *sample(k))
    assert w.close() == tmp_path / 'one'
    meta = metadata(tmp_path / 'one')
    assert meta['relative_file_paths'] == [f'one_{i}.mcap' for i in range(5)]
    assert [f['message_count'] for f in meta['files']] == [1] * 5
    # independent of our merge: the start and duration from the messages themselves
    assert meta['starting_time']['nanoseconds_since_epoch'] == T0
    assert meta['duration']['nanoseconds'] == 4 * NS
    assert meta['topics_with_message_count'][0]['message_count'] == 5
    assert values(tmp_path / 'one') == ([0.0, 1.0, 2.0, 3.0, 4.0], None)
    with Reader(tmp_path / 'one') as r:
        assert [t for _, t, _ in r.messages()] == [T0 + k * NS for k in range(5)]


def test_a_crash_leaves_the_finished_files_as_a_bag_and_nothing_under_the_name(tmp_path):
    w = open_split(tmp_path / 'crash', max_bytes=1)
    for k in range(4):
        w.write(TOPIC, *sample(k))
    w.flush()       # the flush timer's work: the fourth message reaches the disk
    # the process dies here: nothing is closed
    assert not (tmp_path / 'crash').exists()
    partial = w.bagdir
    assert partial.parent.name.startswith('.crash.partial-')
    # the three finished files, with their metadata; the fourth is in its own .partial
    assert metadata(partial)['relative_file_paths'] == [f'crash_{i}.mcap' for i in range(3)]
    assert values(partial) == ([0.0, 1.0, 2.0], None)
    assert len(list(partial.parent.glob('.crash_3.partial-*'))) == 1
    # one reindex of what the recorder left makes one bag of all four, nothing left over
    assert reindex.main([str(partial.parent)]) == 0
    assert values(tmp_path / 'crash') == ([0.0, 1.0, 2.0, 3.0], None)
    assert metadata(tmp_path / 'crash')['relative_file_paths'] == \
        [f'crash_{i}.mcap' for i in range(4)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ['crash']


def test_a_file_finished_but_not_moved_is_taken_in_by_close_and_by_reindex(tmp_path):
    # the split closed file 1 as a bag crash_1 beside crash and stopped before moving it in
    for call in ('close', 'reindex'):
        w = open_split(tmp_path / call, max_bytes=1)
        for k in range(2):
            w.write(TOPIC, *sample(k))
        current, w._current = w._current, None
        current.close()                             # -> <hidden>/<call>_1/<call>_1.mcap
        assert (w.bagdir.parent / f'{call}_1' / f'{call}_1.mcap').is_file()
        if call == 'close':
            w.close()
        else:
            assert reindex.main([str(w.bagdir.parent)]) == 0
        assert values(tmp_path / call) == ([0.0, 1.0], None), call
    assert sorted(p.name for p in tmp_path.iterdir()) == ['close', 'reindex']


def test_a_full_disk_in_a_later_file_keeps_everything_written_before(tmp_path, monkeypatch):
    # a disk of 9000 bytes for all the files together
    used = {}
    real = mcap_file.OutputFile.write_some

    def write_some(self, view):
        room = 9000 - sum(used.values())
        if room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = real(self, view[:room])
        used[self.path] = used.get(self.path, 0) + n
        return n
    monkeypatch.setattr(mcap_file.OutputFile, 'write_some', write_some)
    w = open_split(tmp_path / 'full', max_bytes=1500, chunk_size=300)
    written = 0
    with pytest.raises(DiskFullError):
        for k in range(1000):
            w.write(TOPIC, *sample(k))
            written += 1
    assert w.close() == tmp_path / 'full'
    assert isinstance(w.error, DiskFullError)
    got, damage = values(tmp_path / 'full')
    meta = metadata(tmp_path / 'full')
    assert damage is None and len(meta['relative_file_paths']) >= 2
    assert 0 < len(got) <= written
    assert got == [float(k) for k in range(len(got))], 'a run of what was written, in order'
    assert w.counts == {TOPIC: len(got)} and meta['message_count'] == len(got)
    assert 'disk is full' in meta['custom_data']['tskf_ros.incomplete']
    assert sorted(p.name for p in tmp_path.iterdir()) == ['full']


def test_overwrite_replaces_only_our_own_split_bag(tmp_path):
    for round_ in range(2):
        w = open_split(tmp_path / 'b', max_bytes=1, overwrite=round_ > 0)
        for k in range(3 - round_):
            w.write(TOPIC, *sample(k))
        w.close()
    assert values(tmp_path / 'b') == ([0.0, 1.0], None)
    assert sorted(p.name for p in (tmp_path / 'b').iterdir()) == \
        ['b_0.mcap', 'b_1.mcap', 'metadata.yaml']
    (tmp_path / 'b' / 'notes.txt').write_text('mine')
    with pytest.raises(BagExistsError, match='also holds notes.txt'):
        open_split(tmp_path / 'b', max_bytes=1, overwrite=True)
    with pytest.raises(BagExistsError, match='exists already'):
        open_split(tmp_path / 'b', max_bytes=1)


FULL_DISK_SCRIPT = """
import json, os, sys
from pathlib import Path
from rclpy.serialization import serialize_message
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.split_bag import SplitBagWriter
from tskf_ros.bag.writer import BagWriteError
from tskf_ros.messages import conversions

disk, size, max_bytes, flush_every = Path(sys.argv[1]), *map(int, sys.argv[2:5])
w = SplitBagWriter(disk / 'rec', max_bytes=max_bytes, chunk_size=64 * 1024)
w.open()
w.add_topic('/p', 'sensor_msgs/msg/Illuminance')
written = 0
try:
    for k in range(10 ** 6):
        msg = conversions.power_to_msg(k * 10 ** 6, float(k), 1.0)
        msg.header.frame_id = 'x' * size
        w.write('/p', k * 10 ** 6, serialize_message(msg))
        written += 1
        if flush_every and written % flush_every == 0:
            w.flush()
except BagWriteError as exc:
    error = str(exc)
closed = None
try:
    w.close()
except BagWriteError as exc:
    closed = str(exc)
reader = BagReader(disk / 'rec') if (disk / 'rec').is_dir() else None
kept = [m.log_time_ns for m in reader.messages()] if reader is not None else []
print(json.dumps({'written': written, 'error': error, 'closed': closed,
                  'kept': [t // 10 ** 6 for t in kept],
                  'damage': str(reader.damage) if reader and reader.damage else None,
                  'left': sorted(os.listdir(disk))}))
"""


def unshare_works() -> bool:
    """Say whether this machine lets a process mount a tmpfs of its own (a user namespace)."""
    try:
        return subprocess.run(['unshare', '-r', '-m', 'true'], capture_output=True,
                              timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


@pytest.mark.skipif(not unshare_works(), reason='no user namespaces: no tmpfs of our own')
@pytest.mark.parametrize('size, max_bytes, flush_every', [
    (900, 200_000, 0),          # the disk fills in a file, between splits
    (3000, 400_000, 7),         # flushed as it goes (the recorder's timer)
    (20_000, 1_000_000, 0),     # large messages, few splits
    (50, 20_000, 0),            # many small files: the disk fills while splitting
])
def test_a_real_full_disk_while_splitting_seals_the_bag(tmp_path, size, max_bytes,
                                                        flush_every):
    # a tmpfs of 4 MiB of its own (a user and mount namespace): ENOSPC from the kernel,
    # wherever the writing is when it comes; the bag is sealed with what reached the disk
    disk = tmp_path / 'disk'
    disk.mkdir()
    script = tmp_path / 'fill.py'
    script.write_text(FULL_DISK_SCRIPT)
    shell = (f'mount -t tmpfs -o size=4m none {disk} && '
             f'{sys.executable} {script} {disk} {size} {max_bytes} {flush_every}')
    proc = subprocess.run(['unshare', '-r', '-m', 'sh', '-c', shell], capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert 'disk is full' in out['error'] or 'No space left on device' in out['error'], out
    assert '.partial' not in out['error'], out              # nothing left to reindex
    assert out['closed'] is None, out                       # sealed, nothing to reindex
    assert out['left'] == ['rec'] and out['damage'] is None, out
    kept = out['kept']
    assert 0 < len(kept) <= out['written']
    assert kept == list(range(len(kept))), 'a run of what was written, in order'
