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

"""play's ros2 bag (Jazzy) options and controls, through the real parser, effects checked."""

import signal
import subprocess
import sys
import threading
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Illuminance
from std_srvs.srv import Trigger

from tskf_ros.bag import keyboard, play_options, player
from tskf_ros.bag.player import Player, PlayerError
from tskf_ros.bag.reader import EXIT_DAMAGED
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions
from tskf_ros.tools.demo_collector import wait_for

from .helpers import BAGS, make_bag as make_power_bag, NS, T0, TIMEOUT, usage_error
from .test_reader import corrupt_bag

# s: the longest time of whole seconds in int64 ns
INT64_S = (2 ** 63 - 1) // NS

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
    parser = play_options.build_parser()
    opts = parser.parse_args(list(argv))
    return opts.bag, play_options.player_options(parser, opts)


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


# -- the player, bad options, damage ------------------------------------------------------

def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


def test_player_selects_remaps_offsets_and_loops(ros_context):
    received = []
    clocks = []
    playing = Player(BAGS / 'owc_cai_td_1hz', rate=1000.0, loop=True, start_offset=250.0,
                     clock_hz=500.0, topics=['/received_power'],
                     remap={'/received_power': '/power'}, context=ros_context)
    client = rclpy.create_node('loop_client', context=ros_context)
    # the bag recorded a best-effort (sensor data) publisher; the playing offers the same
    client.create_subscription(Illuminance, '/power', received.append,
                               QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
    client.create_subscription(Clock, '/clock', clocks.append, QoSProfile(depth=1000))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client)
    try:
        spin_until(executor, lambda: playing.pubs['/received_power'].get_subscription_count()
                   and playing.clock_pub.get_subscription_count(), 'matching')
        executor.add_node(playing)
        # in process, into a queue deeper than two passes: nothing of the best-effort
        # stream is lost; wait until the client has the first pass and the start of the
        # second, and has seen /clock go back (a late tick may publish a whole pass at once
        # and skip the clock's jump: the playing keeps looping until one shows it)
        spin_until(executor, lambda: playing.loops >= 2 and len(received) > 51 and any(
            b.clock.sec < a.clock.sec for a, b in zip(clocks, clocks[1:])),
            lambda: f'two loops and /clock going back (loops {playing.loops}, '
            f'{len(received)} messages, {len(clocks)} clocks)')
    finally:
        executor.shutdown()
        playing.destroy_node()
        client.destroy_node()
    assert set(playing.published) == {'/power'}
    stamps = [conversions.stamp_to_ns(m.header.stamp) // 10**9 - 1_700_000_000
              for m in received]
    # 250 s into a bag that starts at t = 0: t = 250..300 (all of T_d's seconds there)
    first = stamps[:stamps.index(300) + 1]
    assert first == list(range(250, 301))
    assert stamps[len(first)] == 250, 'the loop starts again at the offset'
    times = [conversions.stamp_to_ns(c.clock) for c in clocks]
    assert min(times) >= 1_700_000_250 * 10**9
    assert any(b < a for a, b in zip(times, times[1:])), '/clock jumps back at the loop'


def test_player_refuses_bad_options(ros_context):
    with pytest.raises(PlayerError, match='no topic /nope'):
        Player(BAGS / 'owc_cai_td_1hz', topics=['/nope'], context=ros_context)
    with pytest.raises(PlayerError, match='past the end'):
        Player(BAGS / 'owc_cai_td_1hz', start_offset=1000.0, context=ros_context)
    with pytest.raises(PlayerError, match='rate'):
        Player(BAGS / 'owc_cai_td_1hz', rate=0.0, context=ros_context)


def test_a_remap_on_the_command_line_is_plays_not_rcls(tmp_path, capsys):
    """FROM:=TO after -m is the player's (rclpy's remove_ros_args would take it)."""
    bag = make_bag(tmp_path / 'b', n=3)
    assert player.main(['play', str(bag), '-m', '/a/power:=/p', '--topics', '/a/power',
                        '--playback-duration', '0', '--disable-keyboard-controls',
                        '--wait-for-all-acked', '0', '--ros-args', '-r', '__node:=remapped',
                        '--']) == 0
    assert capsys.readouterr().err.splitlines()[-1] == 'play: published /p 0'
    assert play_options.build_parser().parse_args([str(bag)]).remap == []


@pytest.mark.parametrize('args, text', [
    (['--rate', 'inf'], '--rate must be a finite number > 0, got inf'),
    (['--rate', '0'], '--rate must be a finite number > 0, got 0.0'),
    (['--start-offset', 'nan'], '--start-offset must be a finite number >= 0 and at most '
     f'{INT64_S} s (int64 nanoseconds), got nan'),
    (['--clock', '-1'], '--clock must be a finite number >= 0, got -1.0'),
])
def test_play_refuses_bad_values_before_starting(tmp_path, capsys, args, text):
    bag = make_power_bag(tmp_path / 'bag', range(3))
    with pytest.raises(SystemExit) as exit_:
        player.main(['play', str(bag)] + args)
    assert exit_.value.code == 2
    usage_error(capsys.readouterr().err, 'play', text)


def test_play_reports_damage_when_no_message_could_be_read(tmp_path):
    bag = corrupt_bag(tmp_path / 'bag', n=5, flip=200.0, chunk_size=100_000)
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.player', str(bag)],
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == EXIT_DAMAGED, proc.stderr
    assert 'no messages to play' not in proc.stderr and 'Traceback' not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith('play: bag damaged, nothing could be played: ')
    assert 'chunk CRC mismatch' in lines[0] and 'the 0 message(s) before it' in lines[0]


LISTENER = """
import rclpy, sys
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Illuminance
rclpy.init()
node = rclpy.create_node('stalled_listener')
def matched(info):
    if info.current_count:
        print('matched', flush=True)
node.create_subscription(Illuminance, '/burst', lambda m: None, QoSProfile(
    history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE),
    event_callbacks=SubscriptionEventCallbacks(matched=matched))
rclpy.spin(node)
"""


@pytest.mark.parametrize('wait', [None, '1500'])
def test_play_waits_for_a_reliable_subscriber_that_does_not_acknowledge(tmp_path, ros_context,
                                                                        wait):
    """A subscriber stopped (SIGSTOP) acknowledges nothing: play waits, then names the topic."""
    bag = tmp_path / 'burst'
    with BagWriter(bag) as w:
        w.add_topic('/burst', 'sensor_msgs/msg/Illuminance')
        for k in range(50):
            w.write('/burst', T0 + k * 1000, serialize_message(
                conversions.power_to_msg(T0 + k * 1000, float(k), 1.0)))
    node = rclpy.create_node('burst_control', context=ros_context)
    resume = node.create_client(Trigger, '/player/resume')
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    listener = subprocess.Popen([sys.executable, '-c', LISTENER], stdout=subprocess.PIPE,
                                text=True)
    extra = [] if wait is None else ['--wait-for-all-acked', wait]
    proc = subprocess.Popen([sys.executable, '-m', 'tskf_ros.bag.player', str(bag), '-p',
                             '--disable-keyboard-controls'] + extra,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err = []
    reading = threading.Thread(target=lambda: err.extend(line.rstrip('\n') for line in
                                                         proc.stderr))
    reading.start()
    try:
        # both ends matched: the listener says so, and so does the player (its log)
        assert listener.stdout.readline() == 'matched\n'
        wait_for(executor, lambda: resume.service_is_ready() and any(
            line.endswith('/burst: 1 subscriber(s)') for line in list(err)),
            'the player to match the listener', TIMEOUT)
        listener.send_signal(signal.SIGSTOP)
        future = resume.call_async(Trigger.Request())
        wait_for(executor, lambda: proc.poll() is not None and future.done(),
                 'the player to finish', TIMEOUT)
        reading.join()
        assert proc.returncode == 0, err
        ms = play_options.WAIT_ACKED_MS if wait is None else wait
        assert f'play: not acknowledged by every subscriber within {ms} ms: /burst' in err
        assert err[-1] == 'play: published /burst 50' and 'Traceback' not in err
    finally:
        for p in (proc, listener):
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)
                p.kill()
            p.wait()
        reading.join()
        proc.stderr.close()
        listener.stdout.close()
        executor.shutdown()
        node.destroy_node()
