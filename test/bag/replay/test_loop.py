"""The bag tools' command lines: bounded output, one-line errors, safe paths and type names."""

from pathlib import Path
import subprocess
import sys

import pytest
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader

from tskf_ros.bag import offline_replay, player, recorder, reindex
from tskf_ros.bag.message_types import BagTypeError, message_class
from tskf_ros.bag.reader import BagReader, EXIT_DAMAGED, MetadataError
from tskf_ros.bag.writer import BagExistsError, BagWriter
from tskf_ros.messages import conversions
from tskf_ros.tools import plot_bag, sample_bags

import yaml

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
REPO = Path(__file__).resolve().parent.parent
TIMEOUT = 60.0


def make_bag(path, times_s, *, start_ns=T0, chunk_size=None):
    """Write one Illuminance sample per log time (s after start_ns); return the path."""
    kwargs = {'chunk_size': chunk_size} if chunk_size else {}
    with BagWriter(path, **kwargs) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k, t in enumerate(times_s):
            stamp = start_ns + int(round(t * NS))
            w.write('/received_power', stamp, serialize_message(
                conversions.power_to_msg(stamp, 300.0 + k % 7, 4.0)))
    return path


def error_lines(err):
    """Return the non-empty lines of stderr; there must be no traceback."""
    assert 'Traceback' not in err, err
    return [line for line in err.splitlines() if line.strip()]


def one_line(err, prefix, *words):
    lines = error_lines(err)
    assert len(lines) == 1, err
    assert lines[0].startswith(prefix), lines[0]
    for w in words:
        assert w in lines[0], lines[0]


def usage_error(err, prog, text):
    """Check an argparse usage error: usage lines, then exactly `prog: error: text`."""
    lines = error_lines(err)
    assert lines[0].startswith(f'usage: {prog}'), err
    assert lines[-1] == f'{prog}: error: {text}', err


# -- 1. output bounded by the input, not by the span of the clock ------------------------

def test_a_log_time_gap_gives_one_diagnostics_message_not_one_per_period(tmp_path):
    # 20 messages, 1e5 s apart in the middle: the live node's 1 s timer would fire 1e5
    # times; the offline replay writes one /diagnostics message at the latest due time
    times = list(range(10)) + [1e5 + k for k in range(10)]
    bag = make_bag(tmp_path / 'gap', times)
    res = offline_replay.replay(bag, tmp_path / 'out')
    assert res.read == 20
    assert res.written['/diagnostics'] == 19
    with Reader(tmp_path / 'out') as r:
        diag = [t for c, t, _ in r.messages() if c.topic == '/diagnostics']
    assert len(diag) == 19
    # t = 1..9 s, then the latest due time at the gap (1e5 s), then 1e5 + 1..9 s
    assert diag == [T0 + k * NS for k in range(1, 10)] + \
        [T0 + int(1e5 + k) * NS for k in range(10)]
    assert (tmp_path / 'out' / 'out.mcap').stat().st_size < 200_000


def test_a_clock_that_jumps_to_the_present_finishes(tmp_path):
    # log times of a few seconds (a clock from boot), then the present: 1.7e9 periods
    times = [1.0, 2.0, 3.0] + [1.7e9 + k for k in range(3)]
    bag = make_bag(tmp_path / 'jump', times, start_ns=0)
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.offline_replay', str(bag),
                           str(tmp_path / 'out'), '-q'], capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr
    with Reader(tmp_path / 'out') as r:
        assert r.topics['/diagnostics'].msgcount == 5
        assert r.topics['/received_power'].msgcount == 6


# -- 2. one-line errors -------------------------------------------------------------------

def test_plot_bag_on_a_truncated_bag_plots_what_came_before(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(60), chunk_size=2000)
    mcap = bag / 'bag.mcap'
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) * 6 // 10])
    code = plot_bag.main([str(bag), '--out', str(tmp_path / 'png')])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    one_line(err, 'plot_bag: bag damaged; plotted what came before: ', str(mcap),
             'truncated')
    assert (tmp_path / 'png' / 'estimator.png').is_file()


def test_plot_bag_when_nothing_before_the_damage_writes_nothing(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(10))
    mcap = bag / 'bag.mcap'
    mcap.write_bytes(mcap.read_bytes()[:40])
    code = plot_bag.main([str(bag), '--out', str(tmp_path / 'png')])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    one_line(err, 'plot_bag: bag damaged, nothing before the damage to plot: ', str(mcap),
             'the 0 message(s) before it')
    assert not (tmp_path / 'png').exists()


@pytest.mark.parametrize('args, text', [
    (['--rate', 'inf'], '--rate must be a finite number > 0, got inf'),
    (['--rate', '0'], '--rate must be a finite number > 0, got 0.0'),
    (['--start-offset', 'nan'], '--start-offset must be a finite number >= 0, got nan'),
    (['--clock', '-1'], '--clock must be a finite number >= 0, got -1.0'),
])
def test_play_refuses_bad_values_before_starting(tmp_path, capsys, args, text):
    bag = make_bag(tmp_path / 'bag', range(3))
    with pytest.raises(SystemExit) as exit_:
        player.main(['play', str(bag)] + args)
    assert exit_.value.code == 2
    usage_error(capsys.readouterr().err, 'play', text)


def test_replay_offline_to_the_current_directory_leaves_nothing(tmp_path, capsys,
                                                                monkeypatch):
    bag = make_bag(tmp_path / 'bag', range(5))
    work = tmp_path / 'work'
    work.mkdir()
    monkeypatch.chdir(work)
    assert offline_replay.main([str(bag), '.']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: .: ', 'not a usable bag name')
    assert list(work.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'work']


def test_replay_offline_refuses_to_write_into_its_input(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    assert offline_replay.main([str(bag), str(bag), '--overwrite']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: ', 'the input bag')
    assert sorted(p.name for p in bag.iterdir()) == ['bag.mcap', 'metadata.yaml']


def test_record_to_a_path_under_a_file_is_refused_up_front(tmp_path, capsys):
    (tmp_path / 'file').write_text('x')
    code = recorder.main(['record', '-o', str(tmp_path / 'file' / 'bag'), '--topics', '/x'])
    assert code == 1
    one_line(capsys.readouterr().err, 'record: error: ', 'is not a directory')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['file']


def test_record_to_an_unwritable_path_is_one_line(tmp_path):
    # /proc refuses new directories even to root
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.recorder', '-o',
                           '/proc/tskf_no_such_bag', '--topics', '/x'], capture_output=True,
                          text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 1, proc.stderr
    one_line(proc.stderr, 'record: error: /proc/tskf_no_such_bag: ')


@pytest.mark.parametrize('args, text', [
    (['--topics', '/x', '--flush-interval', '-1'],
     '--flush-interval must be a finite number >= 0, got -1.0'),
    (['--topics', '/bad topic'], 'not a topic name: /bad topic'),
    (['--topics', '/x', '-b', '-1'], '--max-bag-size must be >= 0, got -1'),
    (['--topics', '/x', '-d', '-2'], '--max-bag-duration must be >= 0, got -2'),
    (['--topics', '/x', '--compression-format', 'zstd'],
     '--compression-format needs --compression-mode file or message'),
    (['--topics', '/x', '--exclude-topics', '/y'], '--exclude-topics needs --all or --regex'),
    (['--topics', '/x', '--exclude-regex', 'y'], '--exclude-regex needs --all or --regex'),
    ([], 'need --all, --topics or --regex'),
    (['--topics', '/x', '--custom-data', 'novalue'],
     "--custom-data: expected KEY=VALUE, got 'novalue'"),
])
def test_record_refuses_bad_values(tmp_path, capsys, args, text):
    with pytest.raises(SystemExit) as exit_:
        recorder.main(['record', '-o', str(tmp_path / 'bag')] + args)
    assert exit_.value.code == 2
    usage_error(capsys.readouterr().err, 'record', text)
    assert list(tmp_path.iterdir()) == []


def test_make_sample_bags_refuses_bad_paths_and_seeds(tmp_path, capsys):
    (tmp_path / 'file').write_text('x')
    assert sample_bags.main(['--out', str(tmp_path / 'file'), '--only', 'led_alignment']) == 1
    one_line(capsys.readouterr().err, 'make_sample_bags: error: ', 'is not a directory')
    with pytest.raises(SystemExit) as exit_:
        sample_bags.main(['--out', str(tmp_path), '--seed', '-1'])
    assert exit_.value.code == 2
    usage_error(capsys.readouterr().err, 'make_sample_bags',
                '--seed must be in [0, 2**32), got -1')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['file']


def test_plot_bag_and_reindex_refuse_missing_paths(tmp_path, capsys):
    assert plot_bag.main([str(tmp_path / 'nope')]) == 1
    one_line(capsys.readouterr().err, 'plot_bag: error: ', 'no such bag')
    assert reindex.main([str(tmp_path / 'nope')]) == 1
    one_line(capsys.readouterr().err, 'reindex: error: ', 'no such directory')
    assert list(tmp_path.iterdir()) == []


# -- 3. destructive or unsafe file handling -----------------------------------------------

def test_overwrite_refuses_a_directory_that_is_not_our_bag(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    victim = tmp_path / 'victim'
    (victim / 'sub').mkdir(parents=True)
    (victim / 'sub' / 'notes.txt').write_text('keep me')
    assert offline_replay.main([str(bag), str(victim), '--overwrite']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: ',
             'not a bag written by tskf_ros')
    assert (victim / 'sub' / 'notes.txt').read_text() == 'keep me'
    # our own bag with an extra file in it is refused as well
    out = tmp_path / 'out'
    assert offline_replay.main([str(bag), str(out), '-q']) == 0
    (out / 'notes.txt').write_text('mine')
    with pytest.raises(BagExistsError, match='also holds notes.txt'):
        BagWriter(out, overwrite=True).open()
    (out / 'notes.txt').unlink()
    assert offline_replay.main([str(bag), str(out), '-q', '--overwrite']) == 0
    # a rosbag2 bag of someone else (no marker) is refused
    meta = out / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['custom_data'] = None
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagExistsError, match='no tskf_ros.writer in its custom_data'):
        BagWriter(out, overwrite=True).open()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'out', 'victim']


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


def test_type_names_are_checked_and_nothing_else_is_imported():
    code = (
        'import sys\n'
        'from tskf_ros.bag.message_types import message_class, BagTypeError\n'
        "for name in ('this/msg/X', 'antigravity/msg/X', 'os/msg/PathLike', "
        "'tskf_ros/msg/X', 'sensor_msgs/msg/../X', 'sensor_msgs/srv/SetCameraInfo', "
        "'Sensor_msgs/msg/X', 'sensor_msgs/msg/illuminance', 'sensor_msgs/msg/Nope'):\n"
        '    try:\n'
        '        message_class(name)\n'
        "        print('ACCEPTED', name)\n"
        '    except BagTypeError as exc:\n'
        "        print('refused:', exc)\n"
        "print(sorted(m for m in ('this', 'antigravity', 'webbrowser') if m in sys.modules))\n")
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[-1] == '[]'
    assert len(lines) == 10 and all(line.startswith('refused: ') for line in lines[:-1]), \
        proc.stdout
    assert 'Zen of Python' not in proc.stdout
    assert lines[0] == 'refused: message type this/msg/X is not installed here ' \
        '(no interface package this)'
    assert lines[6] == "refused: 'Sensor_msgs/msg/X' is not a message type name " \
        '(package/msg/Name)'
    assert message_class('sensor_msgs/msg/Illuminance').__name__ == 'Illuminance'
    with pytest.raises(BagTypeError):
        message_class('os/msg/PathLike')


def test_a_bag_of_an_unknown_package_type_is_refused_in_one_line(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['topics_with_message_count'][0]['topic_metadata'][
        'type'] = 'this/msg/X'
    meta.write_text(yaml.safe_dump(doc))
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == 1
    out = capsys.readouterr()
    assert 'Zen' not in out.out
    one_line(out.err, 'plot_bag: error: ', 'this/msg/X')
    assert 'this' not in sys.modules
