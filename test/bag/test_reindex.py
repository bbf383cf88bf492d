"""reindex: a crashed recording (SIGKILL, power loss) becomes a bag rosbags and mcap read."""

import os

from rosbags.rosbag2 import Reader

from tskf_ros.bag import reindex
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
