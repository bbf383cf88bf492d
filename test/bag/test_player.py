"""play's ros2 bag (Jazzy) options and controls, through the real parser, effects checked."""

import io
import os
import select
import signal
import subprocess
import sys
import termios
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Illuminance
from std_srvs.srv import Trigger

from tskf_ros.bag import keyboard, player
from tskf_ros.bag.player import Player, PlayerError
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions
from tskf_ros.tools.demo_collector import wait_for

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
# s: a bound on waiting for DDS, never an assertion about timing
TIMEOUT = 60.0
TOPICS = ('/a/power', '/a/angle', '/b/power')


def make_bag(path, n=10):
    """Write n messages per topic of TOPICS, 1 s apart from T0 (value k at T0 + k s)."""
    with BagWriter(path) as w:
        for topic in TOPICS:
            w.add_topic(topic, 'sensor_msgs/msg/Illuminance')
        for k in range(n):
            for topic in TOPICS:
                w.write(topic, T0 + k * NS, serialize_message(
                    conversions.power_to_msg(T0 + k * NS, float(k), 1.0)))
    return path


def options(*argv):
    """Parse a play command line as the command does; return (bag, Player kwargs)."""
    parser = player.build_parser()
    opts = parser.parse_args(list(argv))
    return opts.bag, player.player_options(parser, opts)


def play(context, argv, *, until=None, controls=None):
    """
    Play through the parser, in this process, into reliable subscriptions; return what came.

    Returns (player, {topic: [values]}).  `controls(player, executor)` runs before playing
    to the end (for pause and step tests); `until` replaces waiting for the end.
    """
    bag, kwargs = options(*argv)
    node = Player(bag, context=context, **kwargs)
    got: dict = {}
    client = rclpy.create_node('play_flags_client', context=context)
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
    for topic in node.pubs:
        out = node.out_topic[topic]
        got[out] = []
        client.create_subscription(
            Illuminance, out, lambda m, out=out: got[out].append(m.illuminance), qos)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(client)
    try:
        wait_for(executor, lambda: all(p.get_subscription_count() for p in node.pubs.values()),
                 'matching', TIMEOUT)
        executor.add_node(node)
        if controls is not None:
            controls(node, executor)
        wait_for(executor, until or (lambda: node.done.done() and sum(
            map(len, got.values())) == sum(node.published.values())),
            lambda: f'the end of playing (published {node.published})', TIMEOUT)
    finally:
        executor.shutdown()
        node.destroy_node()
        client.destroy_node()
    return node, got


def test_clock_is_off_by_default_and_a_bare_clock_is_40_hz(tmp_path, ros_context):
    bag = make_bag(tmp_path / 'b')
    assert options(str(bag))[1]['clock_hz'] == 0.0
    assert options(str(bag), '--clock')[1]['clock_hz'] == 40.0
    assert options(str(bag), '--clock', '100')[1]['clock_hz'] == 100.0
    node = Player(bag, context=ros_context, **options(str(bag))[1])
    try:
        assert node.clock_pub is None
        assert '/clock' not in dict(node.get_topic_names_and_types())
    finally:
        node.destroy_node()
    node = Player(bag, context=ros_context, **options(str(bag), '--clock')[1])
    try:
        assert node.clock_period_ns == NS // 40
    finally:
        node.destroy_node()


@pytest.mark.parametrize('argv, values', [
    (['--playback-until-sec', str((T0 + 4 * NS + NS // 2) / NS)], [0, 1, 2, 3, 4]),
    (['--playback-until-nsec', str(T0 + 4 * NS)], [0, 1, 2, 3, 4]),     # inclusive
    (['--playback-duration', '2.5'], [0, 1, 2]),
    (['--playback-duration', '2', '--start-offset', '3'], [3, 4, 5]),
    # rosbag2: with both, the later one stops
    (['--playback-duration', '1', '--playback-until-nsec', str(T0 + 3 * NS)], [0, 1, 2, 3]),
    (['--playback-duration', '-1'], list(range(10))),
])
def test_playback_until_and_duration_stop_at_the_right_stamp(tmp_path, ros_context, argv,
                                                             values):
    bag = make_bag(tmp_path / 'b')
    _, got = play(ros_context, [str(bag), '-r', '1000', '--topics', '/a/power'] + argv)
    assert got == {'/a/power': [float(v) for v in values]}


def test_playback_duration_zero_plays_nothing(tmp_path, ros_context):
    bag = make_bag(tmp_path / 'b')
    node, got = play(ros_context, [str(bag), '-r', '1000', '--playback-duration', '0'])
    assert node.published == {t: 0 for t in TOPICS}


def test_until_sec_and_nsec_are_mutually_exclusive(tmp_path, capsys):
    with pytest.raises(SystemExit):
        options('b', '--playback-until-sec', '1', '--playback-until-nsec', '1')
    assert 'not allowed with argument' in capsys.readouterr().err


@pytest.mark.parametrize('argv, played', [
    (['--topics', '/a/power', '/b/power'], {'/a/power', '/b/power'}),
    (['-e', '/a/.*'], {'/a/power', '/a/angle'}),
    (['--topics-regex', '/a/.*', '-x', '.*angle'], {'/a/power'}),
    (['--regex', '/b/power', '--topics', '/a/angle'], {'/a/angle', '/b/power'}),
    (['--exclude-topics', '/a/angle', '/b/power'], {'/a/power'}),
    (['--exclude-regex', '/a/.*'], {'/b/power'}),
    (['-x', 'power'], set(TOPICS)),       # a whole-name match, as rosbag2's player
])
def test_topic_selection(tmp_path, ros_context, argv, played):
    bag = make_bag(tmp_path / 'b', n=3)
    node, got = play(ros_context, [str(bag), '-r', '1000'] + argv)
    assert set(got) == played
    assert all(v == [0.0, 1.0, 2.0] for v in got.values())


def test_a_selection_of_nothing_and_a_bad_regex_are_refused(tmp_path, ros_context, capsys):
    bag = make_bag(tmp_path / 'b', n=3)
    with pytest.raises(PlayerError, match='nothing to play'):
        Player(bag, context=ros_context, **options(str(bag), '-e', 'power')[1])
    with pytest.raises(SystemExit):
        options(str(bag), '-e', '(')
    assert capsys.readouterr().err.splitlines()[-1].startswith(
        'play: error: --regex: not a regular expression')


def test_remap_short_option_and_qos_overrides(tmp_path, ros_context):
    bag = make_bag(tmp_path / 'b', n=3)
    qos = tmp_path / 'qos.yaml'
    qos.write_text('/a/power:\n  reliability: best_effort\n  durability: transient_local\n'
                   '  history: keep_last\n  depth: 3\n')
    _, kwargs = options(str(bag), '-m', '/a/angle:=/angle', '--topics', '/a/angle',
                        '/a/power', '--qos-profile-overrides-path', str(qos))
    kwargs['qos_overrides'] = player.load_qos_overrides(qos)
    node = Player(bag, context=ros_context, **kwargs)
    try:
        assert node.out_topic == {'/a/power': '/a/power', '/a/angle': '/angle'}
        profile = node.pubs['/a/power'].qos_profile
        assert profile.reliability == ReliabilityPolicy.BEST_EFFORT
        assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL and profile.depth == 3
        assert node.pubs['/a/angle'].qos_profile.reliability == ReliabilityPolicy.RELIABLE
    finally:
        node.destroy_node()


def test_storage_must_be_the_bags(tmp_path, capsys):
    bag = make_bag(tmp_path / 'b', n=3)
    assert player.main(['play', str(bag), '-s', 'sqlite3']) == 1
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == f'play: error: {bag}: the bag is mcap, not sqlite3 (--storage)'
    assert options(str(bag), '-s', 'mcap')[1]['storage'] == 'mcap'


def spin_past(executor, node, wall_s):
    """Spin for wall_s seconds of wall time (what a paused player must sit through)."""
    end = time.monotonic() + wall_s
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def test_start_paused_publishes_nothing_until_stepped_or_resumed(tmp_path, ros_context):
    bag = make_bag(tmp_path / 'b')

    def controls(node, executor):
        # at -r 1000 the whole bag (9 s) is due after 9 ms; paused, nothing may come
        spin_past(executor, node, 0.3)
        assert node.published == {'/a/power': 0}
        assert node.play_next() and node.play_next()
        assert node.published == {'/a/power': 2} and node.bag_now() == T0 + NS
        spin_past(executor, node, 0.1)
        assert node.published == {'/a/power': 2}
        node.resume()
        assert not node.play_next(), 'play next only when paused (rosbag2)'
    node, got = play(ros_context, [str(bag), '-p', '-r', '1000', '--topics', '/a/power'],
                     controls=controls)
    assert got == {'/a/power': [float(k) for k in range(10)]}


def test_keys_pause_step_and_change_the_rate(tmp_path, ros_context):
    bag = make_bag(tmp_path / 'b')
    node = Player(bag, context=ros_context,
                  **options(str(bag), '--topics', '/a/power', '-r', '0.2')[1])
    keys = keyboard.KeyHandler(node)
    try:
        assert keys.feed(b' ') == ['toggle_paused'] and node.paused
        assert keys.feed(b'\x1b[') == []                # half an escape sequence: waits
        assert keys.feed(b'C') == ['play_next'] and node.published == {'/a/power': 1}
        assert keys.feed(b'\x1b[C\x1b[Cq') == ['play_next'] * 2   # 'q' means nothing
        assert node.published == {'/a/power': 3}
        assert keys.feed(b'\x1b[A\x1b[A') == ['faster'] * 2 and node.rate == pytest.approx(0.4)
        keys.feed(b'\x1b[B' * 3)
        assert node.rate == pytest.approx(0.1), 'rate 0.0 is refused, as in rosbag2'
        assert keys.feed(b' ') == ['toggle_paused'] and not node.paused
    finally:
        node.destroy_node()


def test_keys_are_read_only_from_a_terminal(monkeypatch):
    def no_tty(*args):
        raise AssertionError('termios used on a stream that is not a terminal')
    monkeypatch.setattr(keyboard.termios, 'tcgetattr', no_tty)
    monkeypatch.setattr(keyboard.tty, 'setcbreak', no_tty)
    read, write = os.pipe()
    try:
        with os.fdopen(read, 'r', closefd=False) as pipe:
            assert keyboard.TerminalKeys.open(pipe) is None
    finally:
        os.close(read)
        os.close(write)
    with open(os.devnull) as null:
        assert keyboard.TerminalKeys.open(null) is None
    assert keyboard.TerminalKeys.open(io.StringIO('  ')) is None


def test_pause_resume_and_play_next_services(tmp_path, ros_context):
    bag = make_bag(tmp_path / 'b')
    node = Player(bag, context=ros_context, node_name='svc_player',
                  **options(str(bag), '--topics', '/a/power', '-r', '0.001')[1])
    client_node = rclpy.create_node('svc_client', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    executor.add_node(client_node)

    def call(name):
        client = client_node.create_client(Trigger, f'/svc_player/{name}')
        wait_for(executor, client.service_is_ready, f'service {name}', TIMEOUT)
        future = client.call_async(Trigger.Request())
        wait_for(executor, future.done, f'the answer of {name}', TIMEOUT)
        return future.result()

    try:
        assert call('pause').success and node.paused
        before = node.published['/a/power']     # the message at the start, if a tick came
        assert call('play_next').success and node.published == {'/a/power': before + 1}
        assert call('resume').success and not node.paused
        assert not call('play_next').success
        assert call('toggle_paused').message == 'paused'
    finally:
        executor.shutdown()
        node.destroy_node()
        client_node.destroy_node()


def read_until(fd, text, deadline, seen):
    """Read a process's stderr (fd) until `text` appears; fail at the deadline."""
    while text not in seen[0]:
        assert time.monotonic() < deadline, f'never saw {text!r} in:\n{seen[0]}'
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            chunk = os.read(fd, 4096).decode(errors='replace')
            assert chunk, f'the player ended before {text!r}:\n{seen[0]}'
            seen[0] += chunk


@pytest.mark.slow
def test_keys_typed_in_a_real_terminal_pause_and_resume_the_command(tmp_path):
    bag = make_bag(tmp_path / 'b', n=3)
    master, slave = os.openpty()
    before = termios.tcgetattr(slave)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.player', str(bag), '-r', '0.001', '--topics',
         '/a/power'], stdin=slave, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    seen = ['']
    try:
        deadline = time.monotonic() + TIMEOUT
        fd = proc.stderr.fileno()
        read_until(fd, keyboard.HELP, deadline, seen)
        assert termios.tcgetattr(slave)[3] & termios.ICANON == 0, 'the terminal is in cbreak'
        os.write(master, b' ')
        read_until(fd, ']: paused', deadline, seen)
        os.write(master, b' ')
        read_until(fd, ']: resumed', deadline, seen)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stderr.close()
        after = termios.tcgetattr(slave)
        os.close(master)
        os.close(slave)
    assert proc.returncode == 0, seen[0]
    assert after == before, 'the terminal got its settings back'
