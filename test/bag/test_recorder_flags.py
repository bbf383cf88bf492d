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

"""record's ros2 bag (Jazzy) options, each through the real parser, with its effect checked."""

import datetime
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from recording import latched_source, stop, wait_until_recording
from rosbags.rosbag2 import Reader
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Illuminance, JointState

from tskf_ros.bag import record_options, recorder
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.split_bag import MESSAGE_RECORD_OVERHEAD
from tskf_ros.messages import conversions
from tskf_ros.tools.demo_collector import wait_for

import yaml

from .helpers import NS, one_line, T0, TIMEOUT, usage_error

# s: the longest time of whole seconds in int64 ns
INT64_S = (2 ** 63 - 1) // NS

RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                      reliability=ReliabilityPolicy.RELIABLE)


def parsed(*argv):
    """Parse a record command line as the command does; return the Recorder's kwargs."""
    parser = record_options.build_parser()
    opts = parser.parse_args(list(argv))
    record_options.check_options(parser, opts)
    return record_options.recorder_options(opts)


def powers(bag):
    """Return the illuminance values of a bag's /p messages, in storage order."""
    return [deserialize_message(m.data, Illuminance).illuminance
            for m in BagReader(bag).messages(['/p'])]


def record_in_process(context, bag, argv, n, *, clock_step_ns=0):
    """
    Record n reliable Illuminance messages on /p (values 0..n-1) in this process; close.

    With clock_step_ns, /clock is published before each message, advancing by that much
    (the recorder then runs with --use-sim-time from argv).
    """
    kwargs = parsed(*argv)
    source = rclpy.create_node('record_flags_source', context=context)
    pub = source.create_publisher(Illuminance, '/p', RELIABLE)
    clock = source.create_publisher(Clock, '/clock', RELIABLE) if clock_step_ns else None
    rec = recorder.Recorder(bag, context=context, **kwargs)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(rec)
    executor.add_node(source)
    try:
        wait_for(executor, lambda: '/p' in rec.counts and pub.get_subscription_count() == 1,
                 'the recorder subscribing to /p', TIMEOUT)
        for k in range(n):
            if clock is not None:
                t = T0 + (k + 1) * clock_step_ns
                clock.publish(Clock(clock=conversions.ns_to_stamp(t)))
                wait_for(executor, lambda: rec.get_clock().now().nanoseconds == t,
                         'the recorder clock to follow /clock', TIMEOUT)
            pub.publish(conversions.power_to_msg(T0 + k * NS, float(k), 1.0))
            wait_for(executor, lambda: rec.counts['/p'] == k + 1, f'message {k}', TIMEOUT)
        return rec, rec.close()
    finally:
        executor.shutdown()
        rec.destroy_node()
        source.destroy_node()


def check_split(bag, n):
    """Each file is a sealed MCAP file of its own; together they hold 0..n-1 in order."""
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    names = meta['relative_file_paths']
    assert names == [f'{bag.name}_{i}.mcap' for i in range(len(names))]
    assert sorted(p.name for p in bag.iterdir()) == sorted(names + ['metadata.yaml'])
    assert [f['path'] for f in meta['files']] == names
    per_file = []
    for name in names:
        reader = BagReader(bag / name)
        per_file.append([deserialize_message(m.data, Illuminance).illuminance
                         for m in reader.messages()])
        assert reader.damage is None
        with (bag / name).open('rb') as f:     # sealed: a summary the library reads
            summary = make_reader(f).get_summary()
        assert summary is not None and summary.statistics.message_count == len(per_file[-1])
        assert per_file[-1], f'{name} is empty'
    assert [f['message_count'] for f in meta['files']] == [len(v) for v in per_file]
    assert [v for values in per_file for v in values] == [float(k) for k in range(n)]
    assert powers(bag) == [float(k) for k in range(n)]
    with Reader(bag) as r:                     # rosbags reads the split bag as one
        assert r.message_count == n
        assert len(list(r.messages())) == n
    return meta, per_file


def test_default_output_is_rosbag2s_date_and_time_name():
    assert record_options.default_output(datetime.datetime(2024, 5, 6, 7, 8, 9)) == \
        Path('rosbag2_2024_05_06-07_08_09')


def test_record_without_output_names_the_bag_from_the_date(tmp_path):
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.recorder', '--topics', '/x:std_msgs/msg/String'],
        cwd=tmp_path, env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    try:
        deadline = time.monotonic() + TIMEOUT
        while not list(tmp_path.glob('.rosbag2_*.partial-*')):
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, 'the recorder never opened its bag'
            time.sleep(0.05)            # polling a condition, with a deadline
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    bags = [p.name for p in tmp_path.iterdir()]
    assert len(bags) == 1 and re.fullmatch(r'rosbag2_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d', bags[0])
    assert (tmp_path / bags[0] / 'metadata.yaml').is_file()


def test_positional_topics_still_work_with_a_deprecation_warning(tmp_path, capsys):
    (tmp_path / 'file').write_text('x')
    assert recorder.main(['record', '-o', str(tmp_path / 'file' / 'bag'), '/x']) == 1
    lines = capsys.readouterr().err.splitlines()
    assert lines[0].startswith('[WARN] [record]: positional topics are deprecated')
    assert lines[1].startswith('record: error: ')
    assert parsed('/a', '/b')['topic_filter'].topics == ['/a', '/b']
    with pytest.raises(SystemExit):         # a mutually exclusive group, as in Jazzy
        parsed('/a', '--topics', '/b')
    capsys.readouterr()
    assert parsed('-a', '--topics', '/a')['topics'] is None
    assert capsys.readouterr().err == \
        '[WARN] [record]: --all overrides --topics (as in ros2 bag record)\n'


def test_max_bag_size_splits_into_valid_files_that_together_hold_everything(
        ros_context, tmp_path):
    bag = tmp_path / 'sized'
    rec, path = record_in_process(ros_context, bag, ['-b', '1500', '--topics', '/p'], 60)
    assert path == bag and rec.counts == {'/p': 60}
    meta, per_file = check_split(bag, 60)
    record = len(rec_payload()) + MESSAGE_RECORD_OVERHEAD
    # a file is closed when its message records reach 1500 bytes: every file but the last
    # holds ceil(1500 / record) messages
    full = -(-1500 // record)
    assert [len(v) for v in per_file[:-1]] == [full] * (len(per_file) - 1)
    assert len(per_file) == -(-60 // full)
    assert meta['message_count'] == 60


def rec_payload():
    """Return the CDR bytes of one /p message (all have the same length)."""
    from rclpy.serialization import serialize_message
    return serialize_message(conversions.power_to_msg(T0, 1.0, 1.0))


def test_max_bag_duration_splits_on_log_time_and_sim_time_waits_for_clock(
        ros_context, tmp_path):
    bag = tmp_path / 'timed'
    # /clock advances 0.3 s before each message: log times T0 + 0.3 k, k = 1..20
    rec, _ = record_in_process(ros_context, bag, ['-d', '1', '--use-sim-time', '--topics',
                                                  '/p'], 20, clock_step_ns=300_000_000)
    meta, per_file = check_split(bag, 20)
    times = [[m.log_time_ns for m in BagReader(bag / f).messages()]
             for f in meta['relative_file_paths']]
    assert [t for ts in times for t in ts] == [T0 + (k + 1) * 300_000_000 for k in range(20)]
    # rosbag2's rule: a message more than 1 s after its file's first starts a new file
    for ts in times:
        assert ts[-1] - ts[0] <= NS
    for ts, nxt in zip(times, times[1:]):
        assert nxt[0] - ts[0] > NS
    assert [len(ts) for ts in times] == [4] * 5


def test_use_sim_time_writes_nothing_before_the_first_clock(ros_context, tmp_path):
    kwargs = parsed('--use-sim-time', '--topics', '/p:sensor_msgs/msg/Illuminance')
    source = rclpy.create_node('before_clock_source', context=ros_context)
    pub = source.create_publisher(Illuminance, '/p', RELIABLE)
    rec = recorder.Recorder(tmp_path / 'sim', context=ros_context, **kwargs)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(rec)
    executor.add_node(source)
    try:
        wait_for(executor, lambda: pub.get_subscription_count() == 1, 'matching', TIMEOUT)
        pub.publish(conversions.power_to_msg(T0, 1.0, 1.0))
        wait_for(executor, lambda: rec.before_clock == 1, 'the message', TIMEOUT)
        assert rec.counts == {'/p': 0}
        rec.close()
    finally:
        executor.shutdown()
        rec.destroy_node()
        source.destroy_node()
    assert BagReader(tmp_path / 'sim').message_count == 0


@pytest.mark.parametrize('argv, compressed', [
    ([], False),
    (['--compression-mode', 'file', '--compression-format', 'zstd'], True),
    (['--compression-mode', 'message'], True),
    (['--storage-preset-profile', 'zstd_fast'], True),
])
def test_compression_modes_are_zstd_chunks(ros_context, tmp_path, argv, compressed):
    bag = tmp_path / 'c'
    record_in_process(ros_context, bag, argv + ['--topics', '/p', '-s', 'mcap'], 5)
    with (bag / 'c.mcap').open('rb') as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    assert chunks and {c.compression for c in chunks} == ({'zstd'} if compressed else {''})
    assert powers(bag) == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_storage_sqlite3_is_refused_in_one_line(tmp_path, capsys):
    assert recorder.main(['record', '-o', str(tmp_path / 'b'), '--topics', '/x', '-s',
                          'sqlite3']) == 1
    assert capsys.readouterr().err == \
        'record: error: --storage sqlite3: this recorder writes mcap only\n'
    assert list(tmp_path.iterdir()) == []


def test_regex_exclusions_and_qos_overrides_decide_what_is_subscribed(
        ros_context, tmp_path):
    overrides = tmp_path / 'qos.yaml'
    overrides.write_text('/a/angle:\n  reliability: best_effort\n  history: keep_last\n'
                         '  depth: 7\n')
    kwargs = parsed('-e', '^/a/', '--exclude-regex', 'power', '--exclude-topics', '/a/skip',
                    '--qos-profile-overrides-path', str(overrides), '-p', '20')
    source = rclpy.create_node('regex_source', context=ros_context)
    for name, cls in (('/a/angle', JointState), ('/a/power', Illuminance),
                      ('/a/skip', JointState), ('/b/angle', JointState), ('/a/last', JointState)):
        source.create_publisher(cls, name, RELIABLE)
    rec = recorder.Recorder(tmp_path / 'r', context=ros_context, **kwargs)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(rec)
    executor.add_node(source)
    try:
        wait_for(executor, lambda: {'/a/angle', '/a/last'} <= set(rec.subs),
                 lambda: f'the subscriptions (has {sorted(rec.subs)})', TIMEOUT)
        assert set(rec.subs) == {'/a/angle', '/a/last'}
        qos = rec.subs['/a/angle'].qos_profile
        assert qos.reliability == ReliabilityPolicy.BEST_EFFORT and qos.depth == 7
        assert rec.subs['/a/last'].qos_profile.reliability == ReliabilityPolicy.RELIABLE
        assert [rec.wanted(t) for t in ('/a/x', '/a/power2', '/a/skip', '/b/x', '/_h/x')] == \
            [True, False, False, False, False]
    finally:
        executor.shutdown()
        rec.destroy_node()
        source.destroy_node()
    # --all takes everything but hidden topics, /rosout and /parameter_events
    rec = recorder.Recorder(tmp_path / 'all', context=ros_context, **parsed('-a'))
    try:
        assert [rec.wanted(t) for t in ('/x', '/a/_hidden', '/rosout', '/parameter_events')] \
            == [True, False, False, False]
    finally:
        rec.destroy_node()


@pytest.mark.parametrize('topics', [
    ['/typed:sensor_msgs/msg/Illuminance'],
    ['/typed:sensor_msgs/msg/Illuminance', '/named'],
])
def test_topics_of_the_name_type_form_are_the_only_ones_recorded(
        ros_context, tmp_path, topics):
    # NAME:TYPE is a topic asked for, as NAME is: another topic of the graph is not recorded
    source = rclpy.create_node('typed_source', context=ros_context)
    for name in ('/typed', '/named', '/other'):
        source.create_publisher(Illuminance, name, RELIABLE)
    rec = recorder.Recorder(tmp_path / 'r', context=ros_context,
                            **parsed('--topics', *topics, '-p', '20'))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(rec)
    executor.add_node(source)
    wanted = {t.partition(':')[0] for t in topics}
    try:
        # once the recorder has seen /other in the graph, it has had its chance to take it
        wait_for(executor, lambda: '/other' in dict(rec.get_topic_names_and_types())
                 and wanted <= set(rec.subs),
                 lambda: f'the graph and the subscriptions (has {sorted(rec.subs)})', TIMEOUT)
        rec.discover()
        assert set(rec.subs) == wanted
        assert not rec.wanted('/other')
    finally:
        executor.shutdown()
        rec.destroy_node()
        source.destroy_node()


@pytest.mark.parametrize('text, error', [
    ('/x:\n  reliability: sometimes\n', "/x: reliability 'sometimes' is not one of"),
    ('/x:\n  speed: 3\n', "/x: unexpected key 'speed' for a QoS profile"),
    ('/x:\n  depth: -1\n', '/x: depth -1 is not valid'),
    ('/x:\n  deadline: {sec: 1}\n', '/x: deadline must be {sec: S, nsec: N}'),
    ('[1, 2]\n', 'expected topic names mapped to QoS policies'),
])
def test_a_bad_qos_override_file_is_one_line(tmp_path, capsys, text, error):
    path = tmp_path / 'qos.yaml'
    path.write_text(text)
    assert recorder.main(['record', '-o', str(tmp_path / 'b'), '--topics', '/x',
                          '--qos-profile-overrides-path', str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith(f'record: error: {path}: {error}'), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['qos.yaml']


@pytest.mark.slow
def test_record_command_splits_by_size_and_loses_nothing(tmp_path):
    # the command as a user runs it, 40 messages from a latched_source
    bag = tmp_path / 'split'
    context, node, pub = latched_source('split_source', 'p', [float(k) for k in range(40)])
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.recorder', '-o', str(bag), '--topics', '/p',
         '--max-bag-size', '1000', '--compression-mode', 'file'], env=dict(os.environ),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_until_recording(pub, proc, TIMEOUT, pub.topic_name)
        assert pub.wait_for_all_acked(Duration(seconds=TIMEOUT)), 'never acknowledged'
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        stop(proc, node, context)
    assert proc.returncode == 0, err
    assert f'record: wrote {bag}: /p 40' in err
    meta, per_file = check_split(bag, 40)
    assert len(per_file) >= 3


# -- refused before anything starts: one line --------------------------------------------

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
     f'--flush-interval must be a finite number >= 0 and at most {INT64_S} s (int64 '
     'nanoseconds), got -1.0'),
    (['--topics', '/x', '--flush-interval', '1e308'],
     f'--flush-interval must be a finite number >= 0 and at most {INT64_S} s (int64 '
     'nanoseconds), got 1e+308'),
    (['--topics', '/bad topic'], 'not a topic name: /bad topic'),
    (['--topics', '/x', '-b', '-1'], '--max-bag-size must be >= 0, got -1'),
    (['--topics', '/x', '-d', '-2'], f'--max-bag-duration must be a finite number >= 0 and '
     f'at most {INT64_S} s (int64 nanoseconds), got -2'),
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
