"""play: publish a bag at its recorded pace, with `ros2 bag play`'s (Jazzy) options."""

import argparse
import math
from pathlib import Path
import sys
import time
from typing import Iterator, Optional, Sequence

from builtin_interfaces.msg import Time
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from tskf_ros.bag.bag_options import compile_regex, load_qos_overrides, TopicFilter
from tskf_ros.bag.keyboard import HELP, KeyHandler, TerminalKeys
from tskf_ros.bag.message_types import BagTypeError, message_class, qos_to_rclpy
from tskf_ros.bag.reader import BagError, BagReader, exit_status, RawMessage
from tskf_ros.core.units import NS
from tskf_ros.messages.qos import DEFAULT_DEPTH

EPILOG = """examples:
  play bags/owc_cai_td_1hz --rate 10 --clock
  play bags/owc_cai_td_1hz --topics /received_power -m /received_power:=/power --loop
  play bags/owc_ge_1khz --start-offset 30 --playback-duration 5 -p

The stored bytes are published as they are, in storage (log time) order, at bag time =
start + offset + rate x wall time (frozen while paused).  Keys when stdin is a terminal:
space pause/resume, cursor right next message, cursor up/down rate +-0.1; services
~/pause, ~/resume, ~/toggle_paused, ~/play_next."""

NODE_NAME = 'player'
# Hz: /clock rate of a bare --clock (rosbag2 Jazzy)
CLOCK_HZ = 40.0
# s: how often a terminal is read for keys
KEY_PERIOD = 0.05


class PlayerError(BagError):
    """Bad options for a bag: an unknown topic, a bad remap, an offset past the end."""


class PlayerDamageError(PlayerError):
    """The bag is damaged before its first message to play: `damage` says where."""

    def __init__(self, damage) -> None:
        super().__init__(str(damage))
        self.damage = damage


def until_ns(start_ns: int, playback_duration: float, playback_until_ns: int) -> int:
    """
    Return the last log time to play, by rosbag2's rule (-1: no limit).

    A negative duration or time is no limit; with both, the later one wins; a duration of 0
    plays nothing (rosbag2: play_until 0).
    """
    if playback_duration < 0 and playback_until_ns < 0:
        return -1
    from_duration = -1 if playback_duration < 0 else \
        0 if playback_duration == 0 else start_ns + int(round(playback_duration * NS))
    return max(from_duration, playback_until_ns)


class Player(Node):
    """
    Publish a bag at its recorded pace; `done` completes when it has played (not with loop).

    `published` counts messages per output topic; `damage` is set if the bag was damaged.
    topics (names, all if None) or topic_filter select the topics; pause(), resume(),
    toggle_paused(), play_next() and set_rate() are the controls.
    """

    def __init__(self, bag: Path, *, rate: float = 1.0, loop: bool = False,
                 start_offset: float = 0.0, topics: Optional[Sequence[str]] = None,
                 remap: Optional[dict] = None, clock_hz: float = 0.0, tick: float = 0.001,
                 qos_depth: int = 1000, delay: float = 0.0,
                 topic_filter: Optional[TopicFilter] = None,
                 qos_overrides: Optional[dict] = None, start_paused: bool = False,
                 playback_duration: float = -1.0, playback_until_ns: int = -1,
                 storage: str = '', context=None, node_name: str = NODE_NAME,
                 parameter_overrides: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, parameter_overrides=parameter_overrides)
        if not (math.isfinite(rate) and rate > 0):
            raise PlayerError(f'--rate must be a finite number > 0, got {rate}')
        if not (math.isfinite(start_offset) and start_offset >= 0):
            raise PlayerError(f'--start-offset must be a finite number >= 0, got '
                              f'{start_offset}')
        if not (math.isfinite(clock_hz) and clock_hz >= 0):
            raise PlayerError(f'--clock must be a finite number >= 0, got {clock_hz}')
        if not math.isfinite(playback_duration):
            raise PlayerError(f'--playback-duration must be finite, got {playback_duration}')
        self.reader = BagReader(bag)
        if storage and storage != self.reader.storage:
            raise PlayerError(f'{bag}: the bag is {self.reader.storage}, not {storage} '
                              '(--storage)')
        self.rate, self.loop = float(rate), loop
        remap = dict(remap or {})
        qos_overrides = dict(qos_overrides or {})
        if topics is not None:
            missing = [t for t in topics if t not in self.reader.topics]
            if missing:
                raise PlayerError(f'{bag}: no topic {", ".join(missing)} (topics: '
                                  f'{", ".join(sorted(self.reader.topics))})')
        if topic_filter is not None:
            for name in topic_filter.topics:
                if name not in self.reader.topics:
                    self.get_logger().warning(f'{bag}: no topic {name}; ignored')
        take = topic_filter.take if topic_filter is not None else (
            lambda name: topics is None or name in topics)
        # a bag's own /clock is not played when the player publishes /clock (rosbag2)
        selected = [t for t in self.reader.topics if take(t)
                    and not (clock_hz > 0 and t == '/clock')]
        self.pubs: dict = {}
        self.out_topic: dict = {}
        for topic in selected:
            info = self.reader.topics[topic]
            try:
                cls = message_class(info.msgtype)
            except BagTypeError as exc:
                self.get_logger().warning(f'{topic}: {exc}; not played')
                continue
            if topic in qos_overrides:
                qos = qos_overrides[topic]
            elif info.qos:
                qos = qos_to_rclpy(info.qos[0], depth=qos_depth)
            else:
                qos = QoSProfile(depth=qos_depth, reliability=ReliabilityPolicy.RELIABLE)
            name = remap.get(topic, topic)
            self.out_topic[topic] = name
            self.pubs[topic] = self.create_publisher(cls, name, qos)
        if not self.pubs:
            raise PlayerError(f'{bag}: nothing to play (topics: '
                              f'{", ".join(sorted(self.reader.topics))})')
        self.published: dict = {self.out_topic[t]: 0 for t in self.pubs}
        self.clock_pub = (self.create_publisher(Clock, '/clock', DEFAULT_DEPTH)
                          if clock_hz > 0 else None)
        self.clock_period_ns = int(NS / clock_hz) if clock_hz > 0 else 0
        self.last_clock_wall = 0
        self.offset_ns = int(round(start_offset * NS))
        self.playback_duration = float(playback_duration)
        self.playback_until_ns = int(playback_until_ns)
        self.damage = None
        self.loops = 0
        self.paused = bool(start_paused)
        self.done = Future()
        self._start_pass()
        # --delay: let subscribers match before the first message (only before the first pass)
        self.anchor_wall += int(max(delay, 0.0) * NS)
        self.timer = self.create_timer(tick, self._tick)
        for name, call in (('pause', self.pause), ('resume', self.resume),
                           ('toggle_paused', self.toggle_paused),
                           ('play_next', self.play_next)):
            self.create_service(Trigger, f'~/{name}', self._trigger(call))

    def _messages(self) -> Iterator[RawMessage]:
        return self.reader.messages(self.pubs)

    def _start_pass(self) -> None:
        """(Re)start at the bag's first log time + offset."""
        self._it = self._messages()
        self._next = next(self._it, None)
        if self._next is None:
            if self.reader.damage is not None:
                raise PlayerDamageError(self.reader.damage)
            raise PlayerError(f'{self.reader.path}: no messages to play')
        # the bag's start (all topics, as ros2 bag play), else the first selected message
        first = self.reader.start_ns if self.reader.start_ns is not None else \
            self._next.log_time_ns
        self.bag_start = min(first, self._next.log_time_ns) + self.offset_ns
        while self._next is not None and self._next.log_time_ns < self.bag_start:
            self._next = next(self._it, None)
        if self._next is None:
            raise PlayerError(f'{self.reader.path}: --start-offset is past the end of the bag')
        self.until_ns = until_ns(self.bag_start, self.playback_duration,
                                 self.playback_until_ns)
        self._stop_at_until()
        self.anchor_bag = self.bag_start
        self.anchor_wall = time.monotonic_ns()

    def _stop_at_until(self) -> None:
        if self._next is not None and self.until_ns > -1 and (
                self._next.log_time_ns > self.until_ns or self.until_ns == 0):
            self._next = None

    def _advance(self) -> None:
        self._next = next(self._it, None)
        self._stop_at_until()

    def bag_now(self) -> int:
        """Return the bag time that corresponds to now (frozen while paused)."""
        if self.paused:
            return self.anchor_bag
        return self.anchor_bag + max(int((time.monotonic_ns() - self.anchor_wall) * self.rate),
                                     0)

    def _reanchor(self) -> None:
        self.anchor_bag = self.bag_now()
        self.anchor_wall = time.monotonic_ns()

    def pause(self) -> bool:
        """Stop the bag time; return True (as rosbag2's ~/pause)."""
        if not self.paused:
            self._reanchor()
            self.paused = True
            self.get_logger().info('paused')
        return True

    def resume(self) -> bool:
        """Let the bag time run again from where it stopped."""
        if self.paused:
            self.anchor_wall = time.monotonic_ns()
            self.paused = False
            self.get_logger().info('resumed')
        return True

    def toggle_paused(self) -> bool:
        """Pause if playing, resume if paused."""
        return self.resume() if self.paused else self.pause()

    def set_rate(self, rate: float) -> bool:
        """Change the rate (refused, returning False, unless finite and > 0)."""
        if not (math.isfinite(rate) and rate > 0):
            self.get_logger().warning(f'rate {rate} refused (it must be > 0)')
            return False
        self._reanchor()
        self.rate = float(rate)
        self.get_logger().info(f'rate {self.rate:g}')
        return True

    def play_next(self) -> bool:
        """When paused, publish the next message and move the bag time to it (rosbag2)."""
        if not self.paused or self._next is None:
            return False
        msg = self._next
        self._publish(msg)
        self.anchor_bag = max(self.anchor_bag, msg.log_time_ns)
        self._advance()
        self._publish_clock(self.anchor_bag, time.monotonic_ns(), force=True)
        if self._next is None:
            self._end_of_pass()
        return True

    def _trigger(self, call):
        def serve(request, response):
            response.success = bool(call())
            response.message = 'paused' if self.paused else 'playing'
            return response
        return serve

    def _publish(self, msg: RawMessage) -> None:
        self.pubs[msg.topic].publish(msg.data)
        self.published[self.out_topic[msg.topic]] += 1

    def _publish_clock(self, now: int, wall: int, force: bool = False) -> None:
        if self.clock_pub is not None and (
                force or wall - self.last_clock_wall >= self.clock_period_ns):
            self.last_clock_wall = wall
            sec, nanosec = divmod(now, NS)
            self.clock_pub.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))

    def _tick(self) -> None:
        now = self.bag_now()
        self._publish_clock(now, time.monotonic_ns())
        if self.paused:
            return              # not even a message due at the paused time
        while self._next is not None and self._next.log_time_ns <= now:
            self._publish(self._next)
            self._advance()
        if self._next is None:
            self._end_of_pass()

    def _end_of_pass(self) -> None:
        if self.reader.damage is not None and self.damage is None:
            self.damage = self.reader.damage
            self.get_logger().error(f'bag damaged: {self.damage}')
        if self.loop:
            self.loops += 1
            paused = self.paused
            self._start_pass()
            self.paused = paused
        else:
            self.timer.cancel()
            if not self.done.done():
                self.done.set_result(self.published)


def parse_remaps(specs: Sequence[str]) -> dict:
    """Parse FROM:=TO remaps."""
    out = {}
    for spec in specs:
        src, sep, dst = spec.partition(':=')
        if not sep or not src or not dst:
            raise PlayerError(f'bad remap {spec!r}: expected FROM:=TO')
        out[src] = dst
    return out


def build_parser() -> argparse.ArgumentParser:
    """Return the command line: the spelling, defaults and short options of Jazzy's."""
    parser = argparse.ArgumentParser(
        prog='play', description='Publish a bag at its recorded pace, with the options of '
        'ros2 bag play (Jazzy).', epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('-s', '--storage', default='', choices=['mcap', 'sqlite3'],
                        help="the bag's storage (default: detected)")
    parser.add_argument('-r', '--rate', type=float, default=1.0, help='speed factor (> 0)')
    parser.add_argument('--topics', nargs='+', default=[], metavar='topic',
                        help='play only these topics')
    parser.add_argument('-e', '--regex', '--topics-regex', default='', dest='regex',
                        help='play only topics whose whole name matches this regular '
                        'expression (with --topics: either)')
    parser.add_argument('-x', '--exclude-regex', default='',
                        help='do not play topics whose whole name matches')
    parser.add_argument('--exclude-topics', nargs='+', default=[], metavar='topic',
                        help='topics not to play')
    parser.add_argument('--qos-profile-overrides-path', type=Path, metavar='YAML',
                        help="publisher QoS per topic (rosbag2's YAML format)")
    parser.add_argument('-l', '--loop', action='store_true', help='play again at the end')
    parser.add_argument('--remap', '-m', nargs='+', default=[], metavar='FROM:=TO',
                        help='topic remaps')
    parser.add_argument('--clock', type=float, nargs='?', const=CLOCK_HZ, default=0.0,
                        metavar='HZ', help=f'publish /clock at HZ (bare: {CLOCK_HZ:g}; '
                        'default: not published)')
    parser.add_argument('-d', '--delay', type=float, default=0.0,
                        help='seconds to wait before playing (lets subscribers match)')
    parser.add_argument('--playback-duration', type=float, default=-1.0, metavar='S',
                        help='play this many seconds of the bag (negative: all)')
    until = parser.add_mutually_exclusive_group()
    until.add_argument('--playback-until-sec', type=float, default=-1.0, metavar='T',
                       help='play up to this log time, s since the epoch (negative: all)')
    until.add_argument('--playback-until-nsec', type=int, default=-1, metavar='T',
                       help='play up to this log time, ns since the epoch (negative: all)')
    parser.add_argument('--disable-keyboard-controls', action='store_true',
                        help='do not read keys from a terminal stdin')
    parser.add_argument('-p', '--start-paused', action='store_true',
                        help='start paused (resume with space or ~/resume)')
    parser.add_argument('--start-offset', type=float, default=0.0,
                        help='seconds into the bag to start from')
    return parser


def player_options(parser: argparse.ArgumentParser, opts: argparse.Namespace) -> dict:
    """Check parsed options (usage error, exit 2) and return the Player's keyword arguments."""
    for flag, value, low in (('--rate', opts.rate, None), ('--start-offset', opts.start_offset, 0),
                             ('--delay', opts.delay, 0), ('--clock', opts.clock, 0)):
        if not math.isfinite(value) or (value <= 0 if low is None else value < low):
            parser.error(f'{flag} must be a finite number {"> 0" if low is None else ">= 0"}, '
                         f'got {value}')
    for flag, value in (('--playback-duration', opts.playback_duration),
                        ('--playback-until-sec', opts.playback_until_sec)):
        if not math.isfinite(value):
            parser.error(f'{flag} must be a finite number, got {value}')
    until = (int(round(opts.playback_until_sec * NS)) if opts.playback_until_sec >= 0
             else opts.playback_until_nsec)
    try:
        topic_filter = TopicFilter(
            topics=list(opts.topics), regex=compile_regex('--regex', opts.regex),
            exclude_topics=list(opts.exclude_topics),
            exclude_regex=compile_regex('--exclude-regex', opts.exclude_regex),
            whole_name=True)
    except BagError as exc:
        parser.error(str(exc))
    return {'rate': opts.rate, 'loop': opts.loop, 'start_offset': opts.start_offset,
            'topic_filter': topic_filter, 'remap': parse_remaps(opts.remap),
            'clock_hz': opts.clock, 'delay': opts.delay, 'start_paused': opts.start_paused,
            'playback_duration': opts.playback_duration, 'playback_until_ns': until,
            'storage': opts.storage}


def main(args: Optional[list] = None, stdin=None) -> int:
    """Play a bag; return the exit status (keys are read from stdin if it is a terminal)."""
    argv = remove_ros_args(sys.argv if args is None else args)[1:]
    parser = build_parser()
    opts = parser.parse_args(argv)
    try:
        kwargs = player_options(parser, opts)
        kwargs['qos_overrides'] = load_qos_overrides(opts.qos_profile_overrides_path)
    except BagError as exc:
        print(f'play: error: {exc}', file=sys.stderr)
        return 1
    if not opts.bag.exists():
        print(f'play: error: {opts.bag}: no such bag (file or directory)', file=sys.stderr)
        return 1
    rclpy.init(args=args)
    node = keys = None
    try:
        node = Player(opts.bag, **kwargs)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        keys = None if opts.disable_keyboard_controls else TerminalKeys.open(stdin)
        if keys is not None:
            handler = KeyHandler(node)
            node.create_timer(KEY_PERIOD, lambda: handler.feed(keys.read()))
            node.get_logger().info(HELP)
        executor.spin_until_future_complete(node.done)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except PlayerDamageError as exc:
        return exit_status('play', exc.damage, 'bag damaged, nothing could be played')
    except BagError as exc:
        print(f'play: error: {exc}', file=sys.stderr)
        return 1
    except Exception:
        # a SIGINT or SIGTERM shuts the context down while the executor may be building its
        # wait set, which then raises rclpy's RCLError: an interrupt, not a failure
        if rclpy.ok():
            raise
    finally:
        if keys is not None:
            keys.close()
        if node is not None:
            print('play: published ' + ', '.join(
                f'{t} {n}' for t, n in sorted(node.published.items())), file=sys.stderr)
            node.destroy_node()
        rclpy.try_shutdown()
    return exit_status('play', node.damage if node is not None else None, 'bag damaged')


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    console_main()
