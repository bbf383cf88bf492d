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

"""play: publish a bag at its recorded pace, with `ros2 bag play`'s (Jazzy) options."""

import math
from pathlib import Path
import sys
import time
from typing import Iterator, Optional, Sequence

from builtin_interfaces.msg import Time
import rclpy
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from tskf_ros.bag.bag_errors import check_exists
from tskf_ros.bag.bag_options import (load_qos_overrides, OptionError, seconds_ns,
                                      split_ros_args, TopicFilter)
from tskf_ros.bag.keyboard import HELP, KeyHandler, TerminalKeys
from tskf_ros.bag.message_types import BagTypeError, message_class, qos_to_rclpy
from tskf_ros.bag.play_options import build_parser, player_options, PlayerError
from tskf_ros.bag.reader import BagError, BagReader, exit_status, RawMessage
from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.messages.context import end_context
from tskf_ros.messages.qos import DEFAULT_DEPTH

NODE_NAME = 'player'
# s: how often a terminal is read for keys
KEY_PERIOD = 0.05
# s: the longest single wait for acknowledgements (Ctrl-C is seen in between)
ACK_SLICE = 0.1
# ns: the most bag time that one look at the wall clock advances (int64 range)
MAX_ADVANCE_NS = float(2 ** 62)


class PlayerDamageError(PlayerError):
    """The bag is damaged before its first message to play: `damage` says where."""

    def __init__(self, damage) -> None:
        super().__init__(str(damage))
        self.damage = damage


def until_ns(start_ns: int, duration_ns: int, playback_until_ns: int) -> int:
    """
    Return the last log time to play, by rosbag2's rule (-1: no limit).

    A negative duration or time is no limit; with both, the later one wins; a duration of 0
    plays nothing (rosbag2: play_until 0).
    """
    if duration_ns < 0 and playback_until_ns < 0:
        return -1
    from_duration = -1 if duration_ns < 0 else 0 if duration_ns == 0 else start_ns + duration_ns
    return max(from_duration, playback_until_ns)


def checked_ns(flag: str, seconds: float, *, above: bool = False) -> int:
    """Return a time option of the Player in ns (seconds_ns); PlayerError if it is refused."""
    try:
        return seconds_ns(flag, seconds, above=above)
    except OptionError as exc:
        raise PlayerError(str(exc)) from None


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
        self.offset_ns = checked_ns('--start-offset', start_offset)
        delay_ns = checked_ns('--delay', delay)
        if not (math.isfinite(clock_hz) and clock_hz >= 0):
            raise PlayerError(f'--clock must be a finite number >= 0, got {clock_hz}')
        self.clock_period_ns = checked_ns('--clock period (1/HZ)', 1.0 / clock_hz,
                                          above=True) if clock_hz > 0 else 0
        self.duration_ns = -1 if playback_duration < 0 else \
            checked_ns('--playback-duration', playback_duration)
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
            self.pubs[topic] = self.create_publisher(
                cls, name, qos, event_callbacks=PublisherEventCallbacks(
                    matched=lambda info, name=name: self.get_logger().info(
                        f'{name}: {info.current_count} subscriber(s)')))
        if not self.pubs:
            raise PlayerError(f'{bag}: nothing to play (topics: '
                              f'{", ".join(sorted(self.reader.topics))})')
        self.published: dict = {self.out_topic[t]: 0 for t in self.pubs}
        self.clock_pub = (self.create_publisher(Clock, '/clock', DEFAULT_DEPTH)
                          if clock_hz > 0 else None)
        self.last_clock_wall = 0
        self.playback_until_ns = int(playback_until_ns)
        self.damage = None
        self.loops = 0
        self.paused = bool(start_paused)
        self.done = Future()
        self._start_pass()
        # --delay: let subscribers match before the first message (only before the first pass)
        self.anchor_wall += delay_ns
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
        self.until_ns = until_ns(self.bag_start, self.duration_ns, self.playback_until_ns)
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
        # at a rate of 1e308 the product is inf: bag time then runs to the end at once
        advance = min((time.monotonic_ns() - self.anchor_wall) * self.rate, MAX_ADVANCE_NS)
        return self.anchor_bag + max(int(advance), 0)

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

    def wait_for_acks(self, timeout_ms: int) -> list[str]:
        """
        Wait until reliable subscribers acknowledged all; return the topics still not.

        rosbag2's --wait-for-all-acked: at most timeout_ms (0: no limit).  It waits in short
        slices, so that Ctrl-C or a shutdown of the context ends it.
        """
        deadline = None if timeout_ms == 0 else time.monotonic() + timeout_ms / 1000
        late = []
        for topic, pub in self.pubs.items():
            while True:
                left = ACK_SLICE if deadline is None else \
                    min(ACK_SLICE, deadline - time.monotonic())
                if pub.wait_for_all_acked(Duration(nanoseconds=max(int(left * NS), 0))):
                    break
                if left <= 0 or not self.context.ok():
                    late.append(self.out_topic[topic])
                    break
        return late

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
            sec, nanosec = divmod(min(max(now, 0), MAX_STAMP_NS), NS)
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


def main(args: Optional[list] = None, stdin=None) -> int:
    """Play a bag; return the exit status (keys are read from stdin if it is a terminal)."""
    argv, ros_args = split_ros_args(sys.argv if args is None else args)
    argv = argv[1:]
    parser = build_parser()
    opts = parser.parse_args(argv)
    try:
        kwargs = player_options(parser, opts)
        kwargs['qos_overrides'] = load_qos_overrides(opts.qos_profile_overrides_path)
    except BagError as exc:
        print(f'play: error: {exc}', file=sys.stderr)
        return 1
    try:
        check_exists(opts.bag)
    except BagError as exc:
        print(f'play: error: {exc}', file=sys.stderr)
        return 1
    rclpy.init(args=['play'] + ros_args)
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
        if node.done.done():
            late = node.wait_for_acks(opts.wait_for_all_acked)
            if late:
                print(f'play: not acknowledged by every subscriber within '
                      f'{opts.wait_for_all_acked} ms: {", ".join(late)}', file=sys.stderr)
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
        end_context()
    return exit_status('play', node.damage if node is not None else None, 'bag damaged')


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
