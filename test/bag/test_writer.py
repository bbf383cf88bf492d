"""Faults the bag writer and recorder survive: a full disk, SIGKILL, silent corruption."""

import errno
import os
from pathlib import Path
import signal
import struct
import subprocess
import sys
import time

from mcap.reader import make_reader
import pytest
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from recording import stop, wait_until_recording
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Illuminance

from tskf_ros.bag import offline_replay, reindex, mcap_file
from tskf_ros.bag.reader import BagReader, EXIT_DAMAGED
from tskf_ros.bag.writer import BagWriter, DiskFullError
from tskf_ros.messages import conversions
from tskf_ros.tools import plot_bag

import yaml

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
TIMEOUT = 30.0
FULL = 'No space left on device'


def power(k):
    """Return the power of sample k in mW: 200 + k, exact in binary."""
    return 200.0 + k


def sample(k):
    stamp = T0 + k * NS
    return stamp, serialize_message(conversions.power_to_msg(stamp, power(k), 4.0))


def read_all(bag):
    """Return (stamps via rosbags, stamps via the mcap package, our reader's damage)."""
    with Reader(bag) as r:
        ours = [t for _, t, _ in r.messages()]
    mcap = next(Path(bag).glob('*.mcap'))
    with mcap.open('rb') as f:
        theirs = [m.log_time for _, _, m in make_reader(f).iter_messages()]
    reader = BagReader(bag)
    mine = [m.log_time_ns for m in reader.messages()]
    assert ours == theirs == mine
    return ours, reader.damage


def values(bag):
    """Return the powers recorded in a bag, in order."""
    return [conversions.msg_to_power(_decode(m))[1] for m in BagReader(bag).messages()]


def install_quota(monkeypatch, limit):
    """Make the MCAP file writes fail with ENOSPC beyond `limit` bytes (a disk that fills)."""
    real = mcap_file.OutputFile.write_some

    def write_some(self, view):
        room = limit - self.pos
        if room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, view[:room])
    monkeypatch.setattr(mcap_file.OutputFile, 'write_some', write_some)


# -- full disk ----------------------------------------------------------------------------

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
    stamps, damage = read_all(bag)
    assert damage is None
    assert stamps == [T0 + k * NS for k in range(flushed)]
    assert w.counts == {'/received_power': flushed}
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
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
        data_end = w._file.pos
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
    assert read_all(bag) == ([T0 + k * NS for k in range(30)], None)


def test_record_command_says_the_disk_filled_and_keeps_the_bag(tmp_path):
    bag = tmp_path / 'rec'
    code = (
        'import errno, os, sys\n'
        'from tskf_ros.bag import mcap_file\n'
        'real = mcap_file.OutputFile.write_some\n'
        'def write_some(self, view):\n'
        '    if self.pos + len(view) > 20000:\n'
        '        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))\n'
        '    return real(self, view)\n'
        'mcap_file.OutputFile.write_some = write_some\n'
        'from tskf_ros.bag.recorder import main\n'
        f"sys.exit(main(['record', '-o', {str(bag)!r}, '/full_power', "
        "'--flush-interval', '0.05']))\n")
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('full_source', context=context)
    pub = node.create_publisher(Illuminance, 'full_power', QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    proc = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        wait_until_recording(pub, proc, TIMEOUT, pub.topic_name)
        deadline = time.monotonic() + TIMEOUT
        k = 0
        while proc.poll() is None:      # publish until the recorder gives up
            assert time.monotonic() < deadline, 'the recorder never stopped'
            pub.publish(conversions.power_to_msg(T0 + k * NS, power(k), 4.0))
            k += 1
            time.sleep(0.002)           # pacing, not synchronisation
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        stop(proc, node, context)
    assert proc.returncode == 1, err
    assert 'Traceback' not in err
    lines = [line for line in err.splitlines() if line.startswith('record: ')]
    assert len(lines) == 1, err
    assert lines[0].startswith(f'record: error: {bag}: the disk is full ({FULL}) after '), err
    stamps, damage = read_all(bag)
    assert damage is None and stamps
    assert f'kept the {len(stamps)} messages written before, closed in {bag} ' in lines[0]
    # what is kept is a run of what was published, in order, nothing skipped
    kept = values(bag)
    assert kept == [kept[0] + i for i in range(len(stamps))]


# -- SIGKILL, power loss: flush interval and reindex ---------------------------------------

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
    w._file.close()
    w._tmp = None
    mcap = snapshot / name / f'{name}.mcap'
    with mcap.open('ab') as f:          # a chunk cut short by the kill
        f.write(bytes([0x06]) + (5000).to_bytes(8, 'little') + b'\0' * 100)
    return snapshot


def test_reindex_turns_a_crashed_recording_into_a_bag(tmp_path, capsys):
    partial = crashed_recording(tmp_path, 40, 7)
    assert not (partial / 'rec' / 'metadata.yaml').exists()
    assert reindex.main([str(partial), '-o', str(tmp_path / 'rec')]) == 0
    assert capsys.readouterr().out == f'reindex: wrote {tmp_path / "rec"} (40 messages)\n'
    stamps, damage = read_all(tmp_path / 'rec')
    assert damage is None
    assert stamps == [T0 + k * NS for k in range(40)]
    with Reader(tmp_path / 'rec') as r:
        assert r.message_count == 40
        assert r.topics['/received_power'].msgtype == 'sensor_msgs/msg/Illuminance'
    assert not partial.exists()
    # and the bag replays
    assert offline_replay.main([str(tmp_path / 'rec'), str(tmp_path / 'est'), '-q']) == 0


def test_reindex_next_to_the_partial_directory_and_in_place(tmp_path, capsys):
    partial = crashed_recording(tmp_path, 12, 3, name='run')
    target = partial.parent / 'run'
    assert reindex.main([str(partial)]) == 0
    assert read_all(target)[0] == [T0 + k * NS for k in range(12)]
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


def test_sigkill_loses_at_most_the_flush_interval(tmp_path, capsys):
    bag = tmp_path / 'killed'
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('kill_source', context=context)
    pub = node.create_publisher(Illuminance, 'kill_power', QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.recorder', '-o', str(bag), '/kill_power',
         '--flush-interval', '0.2'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    on_disk = 0
    try:
        wait_until_recording(pub, proc, TIMEOUT, pub.topic_name)
        deadline = time.monotonic() + TIMEOUT
        k = 0
        while on_disk < 30:             # until flushes have put 30 messages on disk
            assert time.monotonic() < deadline, 'nothing reached the disk'
            pub.publish(conversions.power_to_msg(T0 + k * NS, power(k), 4.0))
            k += 1
            time.sleep(0.01)            # pacing, not synchronisation
            files = list(tmp_path.glob('.killed.partial-*/killed/killed.mcap'))
            if k % 10 == 0 and files and files[0].stat().st_size:
                on_disk = sum(1 for _ in BagReader(files[0]).messages())
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=TIMEOUT)
    finally:
        stop(proc, node, context)
    assert not bag.exists()
    partials = list(tmp_path.glob('.killed.partial-*'))
    assert len(partials) == 1
    assert reindex.main([str(partials[0])]) == 0
    stamps, damage = read_all(bag)
    assert damage is None
    assert len(stamps) >= on_disk
    kept = values(bag)
    assert kept == [kept[0] + i for i in range(len(stamps))]


# -- silent corruption: CRCs --------------------------------------------------------------

def flip_exponent(mcap, value):
    """Flip an exponent bit of the float64 `value` in the file: value * 2**256."""
    data = bytearray(mcap.read_bytes())
    pos = data.index(struct.pack('<d', value))
    data[pos + 7] ^= 0x10
    assert struct.unpack_from('<d', data, pos)[0] == pytest.approx(value * 2.0 ** 256)
    mcap.write_bytes(bytes(data))
    return pos


def corrupt_bag(tmp_path, n=30, flip=206.0, chunk_size=600):
    with BagWriter(tmp_path / 'bag', chunk_size=chunk_size) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(n):
            w.write('/received_power', *sample(k))
    flip_exponent(tmp_path / 'bag' / 'bag.mcap', flip)
    return tmp_path / 'bag'


def test_a_flipped_bit_is_damage_not_a_value(tmp_path, capsys):
    bag = corrupt_bag(tmp_path)
    reader = BagReader(bag)
    got = [conversions.msg_to_power(_decode(m))[1] for m in reader.messages()]
    assert reader.damage is not None
    assert 'corrupt a chunk (chunk CRC mismatch)' in str(reader.damage)
    assert 0 < len(got) <= 6 and max(got) < 206.0
    assert got == [power(k) for k in range(len(got))]
    code = offline_replay.main([str(bag), str(tmp_path / 'est'), '-q'])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    assert err.count('\n') == 1 and 'chunk CRC mismatch' in err and 'Traceback' not in err
    with Reader(tmp_path / 'est') as r:
        assert r.topics['/received_power'].msgcount == len(got)
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == EXIT_DAMAGED
    assert 'chunk CRC mismatch' in capsys.readouterr().err


def _decode(raw):
    from rclpy.serialization import deserialize_message
    return deserialize_message(raw.data, Illuminance)


def test_a_flipped_bit_outside_the_chunks_fails_the_data_crc(tmp_path):
    with BagWriter(tmp_path / 'bag') as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(5):
            w.write('/received_power', *sample(k))
    mcap = tmp_path / 'bag' / 'bag.mcap'
    data = bytearray(mcap.read_bytes())
    index = data.index(bytes([0x07]), 8)         # the message index after the chunk
    while data[index + 9:index + 11] != b'\x01\x00':
        index = data.index(bytes([0x07]), index + 1)
    data[index + 20] ^= 0x01                       # a timestamp in that index
    mcap.write_bytes(bytes(data))
    reader = BagReader(tmp_path / 'bag')
    assert len(list(reader.messages())) == 5
    assert 'data section CRC mismatch' in str(reader.damage)


def test_play_reports_damage_when_no_message_could_be_read(tmp_path):
    bag = corrupt_bag(tmp_path, n=5, flip=200.0, chunk_size=100_000)
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.player', str(bag)],
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == EXIT_DAMAGED, proc.stderr
    assert 'no messages to play' not in proc.stderr and 'Traceback' not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith('play: bag damaged, nothing could be played: ')
    assert 'chunk CRC mismatch' in lines[0] and 'the 0 message(s) before it' in lines[0]
