"""
play: publish a bag's messages at their recorded pace, with /clock (as `ros2 bag play`).

    play bags/owc_cai_td_1hz --rate 10 --clock 100
    play bags/owc_cai_td_1hz --topics /received_power --remap /received_power:=/power --loop
    play bags/owc_ge_1khz --start-offset 30

The serialized bytes are published as they are (never deserialized).  Message i is
published when `(log_time_i - t_start) / rate` seconds of wall time have passed since
the start, t_start being the bag's start time (metadata.yaml) plus --start-offset.  With
--clock HZ, rosgraph_msgs/Clock is published on /clock at HZ with the bag time, so that nodes with
use_sim_time follow the bag; with --loop, the bag restarts at its end, which is a backward
jump of /clock and of the stamps (the estimator re-initialises, as it would on any clock
reset).  Publishers offer the QoS recorded in the bag (reliable when unknown).
"""

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

from tskf_ros.bag.message_types import BagTypeError, message_class, qos_to_rclpy
from tskf_ros.bag.reader import BagError, BagReader, exit_status, RawMessage
from tskf_ros.core.units import NS
from tskf_ros.messages.qos import DEFAULT_DEPTH

NODE_NAME = 'player'


class PlayerError(BagError):
    """Bad options for a bag: an unknown topic, a bad remap, an offset past the end."""


class PlayerDamageError(PlayerError):
    """The bag is damaged before its first message to play: `damage` says where."""

    def __init__(self, damage) -> None:
        super().__init__(str(damage))
        self.damage = damage


class Player(Node):
    """
    Publish a bag at its recorded pace; `done` completes when it has played (not with loop).

    `published` counts messages per output topic; `damage` is set if the bag was damaged.
    """

    def __init__(self, bag: Path, *, rate: float = 1.0, loop: bool = False,
                 start_offset: float = 0.0, topics: Optional[Sequence[str]] = None,
                 remap: Optional[dict] = None, clock_hz: float = 0.0, tick: float = 0.001,
                 qos_depth: int = 1000, delay: float = 0.0, context=None,
                 node_name: str = NODE_NAME,
                 parameter_overrides: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, parameter_overrides=parameter_overrides)
        if not (math.isfinite(rate) and rate > 0):
            raise PlayerError(f'--rate must be a finite number > 0, got {rate}')
        if not (math.isfinite(start_offset) and start_offset >= 0):
            raise PlayerError(f'--start-offset must be a finite number >= 0, got '
                              f'{start_offset}')
        if not (math.isfinite(clock_hz) and clock_hz >= 0):
            raise PlayerError(f'--clock must be a finite number >= 0, got {clock_hz}')
        self.reader = BagReader(bag)
        self.rate, self.loop = float(rate), loop
        remap = dict(remap or {})
        selected = list(self.reader.topics) if topics is None else list(topics)
        missing = [t for t in selected if t not in self.reader.topics]
        if missing:
            raise PlayerError(f'{bag}: no topic {", ".join(missing)} (topics: '
                              f'{", ".join(sorted(self.reader.topics))})')
        self.pubs: dict = {}
        self.out_topic: dict = {}
        for topic in selected:
            info = self.reader.topics[topic]
            try:
                cls = message_class(info.msgtype)
            except BagTypeError as exc:
                self.get_logger().warning(f'{topic}: {exc}; not played')
                continue
            qos = (qos_to_rclpy(info.qos[0], depth=qos_depth) if info.qos
                   else QoSProfile(depth=qos_depth, reliability=ReliabilityPolicy.RELIABLE))
            name = remap.get(topic, topic)
            self.out_topic[topic] = name
            self.pubs[topic] = self.create_publisher(cls, name, qos)
        if not self.pubs:
            raise PlayerError(f'{bag}: nothing to play')
        self.published: dict = {self.out_topic[t]: 0 for t in self.pubs}
        self.clock_pub = (self.create_publisher(Clock, '/clock', DEFAULT_DEPTH)
                          if clock_hz > 0 else None)
        self.clock_period_ns = int(NS / clock_hz) if clock_hz > 0 else 0
        self.last_clock_wall = 0
        self.offset_ns = int(round(start_offset * NS))
        self.damage = None
        self.loops = 0
        self.done = Future()
        self._start_pass()
        # --delay: let subscribers match before the first message (only before the first pass)
        self.wall_start += int(max(delay, 0.0) * NS)
        self.timer = self.create_timer(tick, self._tick)

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
        self.wall_start = time.monotonic_ns()

    def bag_now(self) -> int:
        """Return the bag time that corresponds to now."""
        return self.bag_start + max(int((time.monotonic_ns() - self.wall_start) * self.rate), 0)

    def _tick(self) -> None:
        now = self.bag_now()
        wall = time.monotonic_ns()
        if self.clock_pub is not None and wall - self.last_clock_wall >= self.clock_period_ns:
            self.last_clock_wall = wall
            sec, nanosec = divmod(now, NS)
            self.clock_pub.publish(Clock(clock=Time(sec=sec, nanosec=nanosec)))
        while self._next is not None and self._next.log_time_ns <= now:
            msg = self._next
            self.pubs[msg.topic].publish(msg.data)
            self.published[self.out_topic[msg.topic]] += 1
            self._next = next(self._it, None)
        if self._next is None:
            if self.reader.damage is not None and self.damage is None:
                self.damage = self.reader.damage
                self.get_logger().error(f'bag damaged: {self.damage}')
            if self.loop:
                self.loops += 1
                self._start_pass()
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


def main(args: Optional[list] = None) -> int:
    """Play a bag; return the exit status."""
    argv = remove_ros_args(sys.argv if args is None else args)[1:]
    parser = argparse.ArgumentParser(prog='play', description='Publish a bag at its recorded '
                                     'pace (with /clock for use_sim_time nodes).')
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('-r', '--rate', type=float, default=1.0, help='speed factor')
    parser.add_argument('-l', '--loop', action='store_true', help='play again at the end')
    parser.add_argument('--start-offset', type=float, default=0.0,
                        help='seconds into the bag to start from')
    parser.add_argument('--topics', nargs='+', help='play only these topics')
    parser.add_argument('--remap', nargs='+', default=[], help='FROM:=TO topic remaps')
    parser.add_argument('-d', '--delay', type=float, default=0.0,
                        help='seconds to wait before playing (lets subscribers match)')
    parser.add_argument('--clock', type=float, default=100.0, metavar='HZ',
                        help='publish /clock at HZ (0: off; default 100)')
    opts = parser.parse_args(argv)
    for flag, value, low in (('--rate', opts.rate, None), ('--start-offset', opts.start_offset, 0),
                             ('--delay', opts.delay, 0), ('--clock', opts.clock, 0)):
        if not math.isfinite(value) or (value <= 0 if low is None else value < low):
            parser.error(f'{flag} must be a finite number {"> 0" if low is None else ">= 0"}, '
                         f'got {value}')
    if not opts.bag.exists():
        print(f'play: error: {opts.bag}: no such bag (file or directory)', file=sys.stderr)
        return 1
    rclpy.init(args=args)
    node = None
    try:
        node = Player(opts.bag, rate=opts.rate, loop=opts.loop, start_offset=opts.start_offset,
                      topics=opts.topics, remap=parse_remaps(opts.remap), clock_hz=opts.clock,
                      delay=opts.delay)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin_until_future_complete(node.done)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except PlayerDamageError as exc:
        return exit_status('play', exc.damage, 'bag damaged, nothing could be played')
    except BagError as exc:
        print(f'play: error: {exc}', file=sys.stderr)
        return 1
    finally:
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
