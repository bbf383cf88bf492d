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

"""replay_offline's command line: one-line errors, exit statuses, safe outputs, --npz."""

import shutil
import subprocess
import sys

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader, EXIT_DAMAGED
from tskf_ros.bag.replay import columns
from tskf_ros.bag.replay.cli import main
from tskf_ros.bag.replay.loop import replay_arrays
from tskf_ros.bag.writer import BagWriter

import yaml

from ..helpers import (BAGS, chunk_offsets, make_bag, mcap_file, NS, one_line, scalar_bag, T0,
                       TIMEOUT)
from ..test_reader import flip_in_third_chunk


def run(capsys, *args):
    """Run replay_offline; return (exit status, stdout, stderr)."""
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_error(err, *words):
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith('replay_offline: error: ')
    assert 'Traceback' not in err
    for w in words:
        assert w in lines[0], lines[0]


def test_nonexistent_bag(capsys, tmp_path):
    code, _, err = run(capsys, tmp_path / 'nope', tmp_path / 'out')
    assert code == 1
    one_line_error(err, str(tmp_path / 'nope'), 'no such bag')
    assert not (tmp_path / 'out').exists()


def test_missing_metadata(capsys, tmp_path):
    bag = scalar_bag(tmp_path / 'bag')
    (bag / 'metadata.yaml').unlink()
    code, _, err = run(capsys, bag, tmp_path / 'out')
    assert code == 1
    one_line_error(err, 'metadata.yaml: missing', 'bag.mcap')
    # the hint works: the bare MCAP file is readable
    assert run(capsys, bag / 'bag.mcap', tmp_path / 'out')[0] == 0


def test_empty_file_and_empty_bag(capsys, tmp_path):
    bag = scalar_bag(tmp_path / 'bag')
    (bag / 'bag.mcap').write_bytes(b'')
    code, _, err = run(capsys, bag, tmp_path / 'out')
    assert code == 1
    one_line_error(err, 'bag.mcap', 'empty file (0 bytes)')
    with BagWriter(tmp_path / 'nomsgs') as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
    code, _, err = run(capsys, tmp_path / 'nomsgs', tmp_path / 'out2')
    assert code == 1
    one_line_error(err, 'no messages on /received_power')
    assert not (tmp_path / 'out2').exists()


def test_unknown_type(capsys, tmp_path):
    bag = scalar_bag(tmp_path / 'bag', msgtype='std_msgs/msg/String')
    code, _, err = run(capsys, bag, tmp_path / 'out')
    assert code == 1
    one_line_error(err, 'topic /received_power has type std_msgs/msg/String')
    with BagWriter(tmp_path / 'custom') as w:
        w.add_topic('/received_power', 'acme_msgs/msg/Power', msgdef='float64 watts\n')
        w.write('/received_power', T0, b'\x00\x01\x00\x00' + bytes(8))
    code, _, err = run(capsys, tmp_path / 'custom', tmp_path / 'out')
    assert code == 1
    one_line_error(err, 'acme_msgs/msg/Power')


@pytest.mark.parametrize('damage', ['truncated', 'corrupt'])
def test_damaged_chunk_processes_what_came_before(capsys, tmp_path, damage):
    bag = scalar_bag(tmp_path / 'bag', n=300, filler=12_000, compress=True)
    mcap = bag / 'bag.mcap'
    chunks = chunk_offsets(mcap)
    assert len(chunks) >= 3
    start, length = chunks[1]
    data = bytearray(mcap.read_bytes())
    if damage == 'truncated':
        data = data[:start + 9 + length // 2]
    else:
        # overwrite the start of the chunk's zstd frame (after the 53-byte chunk header).
        # rosbags writes no chunk CRC, so garbage inside the payload of a message would be
        # undetectable; a CRC, when the writer stored one (rosbag2 does), is checked
        data[start + 53:start + 53 + 64] = bytes(range(64))
    mcap.write_bytes(bytes(data))
    before = sum(1 for m in BagReader(bag).messages() if m.topic == '/received_power')
    assert 0 < before < 297
    code, out, err = run(capsys, bag, tmp_path / 'out')
    assert code == EXIT_DAMAGED
    assert 'Traceback' not in err
    words = 'truncated in a chunk' if damage == 'truncated' else 'corrupt a chunk'
    assert words in err and str(mcap) in err and f'at byte {start}' in err
    with Reader(tmp_path / 'out') as r:
        counts = {t: i.msgcount for t, i in r.topics.items()}
    assert counts['/received_power'] == before
    assert counts['/estimate/corrected'] == before - 1
    meta = yaml.safe_load((tmp_path / 'out' / 'metadata.yaml').read_text())
    assert words in meta['rosbag2_bagfile_information']['custom_data']['tskf_ros.input_damage']


def test_refuses_to_overwrite(capsys, tmp_path):
    bag = scalar_bag(tmp_path / 'bag')
    (tmp_path / 'out').mkdir()
    code, _, err = run(capsys, bag, tmp_path / 'out')
    assert code == 1
    one_line_error(err, 'exists already')
    assert run(capsys, bag, tmp_path / 'out', '--overwrite')[0] == 0


def test_sqlite3_storage(capsys, tmp_path):
    bag = scalar_bag(tmp_path / 'bag', storage='sqlite3')
    assert (bag / 'bag.db3').is_file()
    code, out, err = run(capsys, bag, tmp_path / 'out')
    assert code == 0, err
    assert 'sqlite3 storage' in out
    with Reader(tmp_path / 'out') as r:
        assert r.topics['/estimate/corrected'].msgcount == 56


def test_command_line_error_is_one_line_without_traceback(tmp_path):
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.replay.cli',
                           str(tmp_path / 'x')], capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 1
    one_line_error(proc.stderr, 'no such bag')


def test_replay_offline_to_the_current_directory_leaves_nothing(tmp_path, capsys,
                                                                monkeypatch):
    bag = make_bag(tmp_path / 'bag', range(5))
    work = tmp_path / 'work'
    work.mkdir()
    monkeypatch.chdir(work)
    assert main([str(bag), '.']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: .: ', 'not a usable bag name')
    assert list(work.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'work']


def test_replay_offline_refuses_to_write_into_its_input(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    assert main([str(bag), str(bag), '--overwrite']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: ', 'the input bag')
    assert sorted(p.name for p in bag.iterdir()) == ['bag.mcap', 'metadata.yaml']


def test_overwrite_refuses_a_directory_that_is_not_our_bag(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    victim = tmp_path / 'victim'
    (victim / 'sub').mkdir(parents=True)
    (victim / 'sub' / 'notes.txt').write_text('keep me')
    assert main([str(bag), str(victim), '--overwrite']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: ',
             'not a bag written by tskf_ros')
    assert (victim / 'sub' / 'notes.txt').read_text() == 'keep me'
    out = tmp_path / 'out'
    assert main([str(bag), str(out), '-q']) == 0
    assert main([str(bag), str(out), '-q', '--overwrite']) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'out', 'victim']


def test_an_undecodable_measurement_is_damage_with_one_line(tmp_path, capsys):
    """A cut message stops the replay: what came before is written, exit 3, one line."""
    good = serialize_message(message_class('sensor_msgs/msg/Illuminance')(illuminance=1.0))
    with BagWriter(tmp_path / 'bag') as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(5):
            w.write('/received_power', (k + 1) * NS, good if k != 3 else good[:20])
    code = main([str(tmp_path / 'bag'), str(tmp_path / 'est'), '-q'])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    assert err.count('\n') == 1 and 'message 4 on /received_power does not deserialize' in err
    counts = {}
    for m in BagReader(tmp_path / 'est').messages():
        counts[m.topic] = counts.get(m.topic, 0) + 1
    assert counts['/received_power'] == 4      # copied as read, the cut one included
    arrays = replay_arrays(tmp_path / 'bag')
    assert len(arrays['sample.log_ns']) == 3
    assert 'does not deserialize' in str(arrays['meta.damage'])


def test_the_arrays_file_is_whole_or_absent(tmp_path, monkeypatch, capsys):
    out = tmp_path / 'a.npz'

    def fail(source, target, length):     # the disk fills while a column is copied in
        target.write(source.read(100))
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(columns.shutil, 'copyfileobj', fail)
    assert main([str(BAGS / 'owc_cai_td_1hz'), '--npz', str(out), '-q']) == 1
    assert 'No space left on device' in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SystemExit) as info:       # --npz writes no bag: no output with it
        main([str(BAGS / 'owc_cai_td_1hz'), str(tmp_path / 'o'), '--npz', str(out)])
    assert info.value.code == 2 and list(tmp_path.iterdir()) == []
    # a directory or an empty name is refused in one line (was: a traceback for '', and
    # DIR.npz written beside the directory)
    (tmp_path / 'd').mkdir()
    for npz in ('', str(tmp_path / 'd')):
        with pytest.raises(SystemExit) as info:
            main([str(BAGS / 'owc_cai_td_1hz'), '--npz', npz, '-q'])
        err = capsys.readouterr().err.strip().splitlines()
        assert info.value.code == 2 and 'a directory' in err[-1], err
    assert [p.name for p in tmp_path.iterdir()] == ['d'] and not any((tmp_path / 'd').iterdir())


def test_arrays_of_a_damaged_bag_hold_what_came_before_and_exit_3(tmp_path, capsys):
    bag = flip_in_third_chunk(BAGS / 'owc_ge_1khz', tmp_path / 'bag')
    reader = BagReader(bag)
    got = list(reader.messages())
    assert main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q']) == EXIT_DAMAGED
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'CRC mismatch' in err
    with np.load(tmp_path / 'a.npz') as f:
        assert len(f['sample.log_ns']) == sum(m.topic == '/received_power' for m in got)
        assert 'CRC mismatch' in str(f['meta.damage'])


def test_arrays_refuse_a_bag_whose_storage_is_outside_it(tmp_path):
    shutil.copytree(BAGS / 'owc_cai_td_1hz', tmp_path / 'outside')
    bag = tmp_path / 'bag'
    shutil.copytree(BAGS / 'owc_cai_td_1hz', bag)
    name = mcap_file(bag).name
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['relative_file_paths'] = ['../outside/' + name]
    meta.write_text(yaml.safe_dump(doc))
    assert main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q']) == 1
    assert not (tmp_path / 'a.npz').exists()
