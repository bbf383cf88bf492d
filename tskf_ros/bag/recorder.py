"""
record: write chosen topics to a rosbag2 MCAP bag, as `ros2 bag record -s mcap` would.

    record -o /tmp/run1 /received_power /true_angle
    record -o /tmp/run1 --all
    record -o /tmp/run1 /received_power:sensor_msgs/msg/Illuminance   # type given, no wait

Subscribes raw (the serialized CDR bytes are written as they arrive, never deserialized),
with the node clock's time of arrival as the log time (bag time follows /clock with
use_sim_time).  Topic types come from the graph (or NAME:TYPE); a topic is subscribed as
soon as a publisher appears, with a QoS compatible with every publisher's (reliable if all
offer reliable, else best effort; history KEEP_ALL so that a reliable publisher is never
dropped), and the publishers' offered QoS goes to metadata.yaml.  The bag is written into
a hidden .partial directory and renamed when it is closed: on Ctrl-C / SIGTERM the recorder
first takes every message already delivered to its subscriptions (up to DRAIN_LIMIT s),
then closes the bag properly; a bag that was not closed is never left under the final name.

Faults: every --flush-interval seconds (default 1) the chunk in progress is written and
fsynced, so a SIGKILL or a power loss loses at most that much; the hidden .partial
directory left behind is turned into a bag by `reindex`.  When the disk fills (ENOSPC)
the recorder stops, keeps what reached the disk, closes it as a valid bag under the final
name and exits 1 with a one-line error.  A bad output path or option is refused before
anything is subscribed or created.
"""

import argparse
import math
from pathlib import Path
import re
import signal
import sys
import time
from typing import Optional, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from tskf_ros.bag.message_types import BagTypeError, message_class, qos_from_rclpy
from tskf_ros.bag.reader import BagError
from tskf_ros.bag.writer import BagWriteError, BagWriter

NODE_NAME = 'recorder'
# not recorded by --all unless named
INTERNAL_TOPICS = ('/rosout', '/parameter_events')
# a fully qualified topic name (rcl's grammar, without substitutions)
TOPIC_NAME = re.compile(r'/|(/[A-Za-z_][A-Za-z0-9_]*)+')
# s: after a stop signal, keep taking delivered messages for at most this long
DRAIN_LIMIT = 2.0
# s: default interval between flushes (what a SIGKILL or a power loss may lose at most)
FLUSH_INTERVAL = 1.0


class Recorder(Node):
    """
    Record topics to a bag; `close()` finishes the bag.

    topics: names to record (None: all but INTERNAL_TOPICS); types: name -> type for
    topics to subscribe without waiting for the graph.
    """

    def __init__(self, output: Path, *, topics: Optional[Sequence[str]] = None,
                 types: Optional[dict] = None, overwrite: bool = False,
                 compress: bool = False, discovery_period: float = 0.2,
                 flush_interval: float = FLUSH_INTERVAL,
                 context=None, node_name: str = NODE_NAME,
                 parameter_overrides: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, parameter_overrides=parameter_overrides)
        if not (math.isfinite(flush_interval) and flush_interval >= 0):
            raise BagWriteError(f'flush interval must be a finite number >= 0, got '
                                f'{flush_interval}')
        self.writer = BagWriter(output, overwrite=overwrite, compress=compress)
        self.writer.open()
        self.failed: Optional[BagWriteError] = None     # a write failed: stop recording
        self.flusher = (self.create_timer(flush_interval, self.flush) if flush_interval > 0
                        else None)
        self.wanted = None if topics is None else set(topics) | set(types or {})
        self.counts: dict[str, int] = {}
        self.subs: dict = {}
        for topic, msgtype in (types or {}).items():
            self._subscribe(topic, msgtype)
        self.discovery = self.create_timer(discovery_period, self.discover)
        self.discover()
        what = 'all topics' if self.wanted is None else ', '.join(sorted(self.wanted))
        self.get_logger().info(f'recording {what} to {output}')

    def discover(self) -> None:
        """Subscribe to wanted topics that have appeared in the graph."""
        for topic, msgtypes in self.get_topic_names_and_types():
            if topic in self.subs:
                continue
            if self.wanted is None and topic in INTERNAL_TOPICS:
                continue
            if self.wanted is not None and topic not in self.wanted:
                continue
            if len(msgtypes) != 1:
                self.get_logger().warning(f'{topic} has several types {msgtypes}; skipped')
                self.subs[topic] = None
                continue
            if not self.get_publishers_info_by_topic(topic):
                continue
            self._subscribe(topic, msgtypes[0])

    def _subscribe(self, topic: str, msgtype: str) -> None:
        try:
            cls = message_class(msgtype)
        except BagTypeError as exc:
            self.get_logger().error(f'{topic}: {exc}; not recorded')
            self.subs[topic] = None
            return
        if self.writer is None or self.failed is not None:
            return
        infos = self.get_publishers_info_by_topic(topic)
        offered = [i.qos_profile for i in infos]
        reliable = bool(offered) and all(
            p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
        latched = bool(offered) and all(
            p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_ALL, depth=1000,
            reliability=ReliabilityPolicy.RELIABLE if reliable
            else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
            else DurabilityPolicy.VOLATILE)
        try:
            self.writer.add_topic(topic, msgtype, qos=[qos_from_rclpy(p) for p in offered])
        except BagTypeError as exc:
            self.get_logger().error(f'{topic}: {exc}; not recorded')
            self.subs[topic] = None
            return
        except BagWriteError as exc:
            self._fail(exc)
            return
        self.counts[topic] = 0
        clock = self.get_clock()
        write = self.writer.write

        def on_message(data: bytes) -> None:
            if self.failed is not None:
                return
            try:
                write(topic, clock.now().nanoseconds, data)
            except BagWriteError as exc:
                self._fail(exc)
                return
            self.counts[topic] += 1
        self.subs[topic] = self.create_subscription(cls, topic, on_message, qos, raw=True)
        self.get_logger().info(f'subscribed to {topic} ({msgtype}, '
                               f'{"reliable" if reliable else "best effort"})')

    def _fail(self, exc: BagWriteError) -> None:
        if self.failed is None:
            self.failed = exc
            self.get_logger().error(f'{exc}; stopping')

    def flush(self) -> None:
        """Write the chunk in progress and fsync (the timer's callback)."""
        if self.writer is None or self.failed is not None:
            return
        try:
            self.writer.flush()
        except BagWriteError as exc:
            self._fail(exc)

    def close(self) -> Optional[Path]:
        """
        Stop recording and finish the bag; return its path (None if already closed).

        After a failed write (`failed`), the bag holds what reached the disk (BagWriter).
        """
        if self.writer is None:
            return None
        for sub in self.subs.values():
            if sub is not None:
                self.destroy_subscription(sub)
        self.subs.clear()
        self.discovery.cancel()
        if self.flusher is not None:
            self.flusher.cancel()
        writer, self.writer = self.writer, None
        path = writer.close()
        if writer.error is not None:
            self.counts = dict(writer.counts)
        return path

    def destroy_node(self) -> None:
        """Close the bag, then destroy the node."""
        self.close()
        super().destroy_node()


def parse_topics(specs: Sequence[str]) -> tuple[list, dict]:
    """Split NAME or NAME:TYPE specs into names and a name -> type map."""
    names, types = [], {}
    for spec in specs:
        name, _, msgtype = spec.partition(':')
        if not name.startswith('/'):
            name = '/' + name
        if msgtype:
            types[name] = msgtype
        else:
            names.append(name)
    return names, types


def drain(executor: SingleThreadedExecutor, node: Recorder) -> None:
    """
    Take the messages already delivered, until two passes add none or DRAIN_LIMIT passes.

    The node's timers are cancelled first, so that a pass is never spent on them.
    """
    node.discovery.cancel()
    if node.flusher is not None:
        node.flusher.cancel()
    deadline = time.monotonic() + DRAIN_LIMIT
    idle = 0
    while time.monotonic() < deadline and idle < 2 and node.failed is None:
        before = sum(node.counts.values())
        executor.spin_once(timeout_sec=0.05)
        idle = idle + 1 if sum(node.counts.values()) == before else 0


def main(args: Optional[list] = None) -> int:
    """Record until Ctrl-C, SIGTERM or --max-duration; return the exit status."""
    argv = remove_ros_args(sys.argv if args is None else args)[1:]
    parser = argparse.ArgumentParser(prog='record', description='Record topics to a rosbag2 '
                                     'MCAP bag (raw, receive time as log time).')
    parser.add_argument('topics', nargs='*', help='NAME or NAME:TYPE (type from the graph '
                        'if not given)')
    parser.add_argument('-o', '--output', type=Path, required=True, help='bag directory')
    parser.add_argument('-a', '--all', action='store_true', help='record every topic')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    parser.add_argument('--compress', action='store_true', help='zstd chunk compression')
    parser.add_argument('--max-duration', type=float, default=0.0,
                        help='stop after this many seconds (0: until interrupted)')
    parser.add_argument('--flush-interval', type=float, default=FLUSH_INTERVAL, metavar='S',
                        help='write and fsync the chunk in progress every S seconds: what a '
                        f'crash may lose at most (default {FLUSH_INTERVAL:g}; 0: only when '
                        'chunks fill)')
    opts = parser.parse_args(argv)
    if not opts.topics and not opts.all:
        parser.error('name topics to record, or --all')
    for flag, value in (('--max-duration', opts.max_duration),
                        ('--flush-interval', opts.flush_interval)):
        if not (math.isfinite(value) and value >= 0):
            parser.error(f'{flag} must be a finite number >= 0, got {value}')
    names, types = parse_topics(opts.topics)
    bad = [n for n in list(names) + list(types) if not TOPIC_NAME.fullmatch(n)]
    if bad:
        parser.error(f'not a topic name: {bad[0]}')
    try:
        BagWriter(opts.output, overwrite=opts.overwrite).check_target()
    except BagError as exc:
        print(f'record: error: {exc}', file=sys.stderr)
        return 1
    # our own signal handlers: rclpy's would shut the context down before the drain
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, frame: stop.append(signum))
    node = None
    try:
        node = Recorder(opts.output, topics=None if opts.all else names, types=types,
                        overwrite=opts.overwrite, compress=opts.compress,
                        flush_interval=opts.flush_interval)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        if opts.max_duration > 0:
            node.create_timer(opts.max_duration, lambda: stop.append('max-duration'))
        while not stop and node.failed is None:
            executor.spin_once(timeout_sec=0.1)
        if node.failed is None:
            drain(executor, node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (BagError, BagTypeError) as exc:
        print(f'record: error: {exc}', file=sys.stderr)
        return 1
    finally:
        status = 0
        if node is not None:
            failed = node.failed
            try:
                path = node.close()
            except BagError as exc:
                print(f'record: error: {exc}', file=sys.stderr)
                status = 1
            else:
                counts = ', '.join(f'{t} {n}' for t, n in sorted(node.counts.items()))
                if failed is not None:
                    print(f'record: error: {failed}; kept the {sum(node.counts.values())} '
                          f'messages written before, closed in {path} ({counts})',
                          file=sys.stderr)
                    status = 1
                else:
                    print(f'record: wrote {path}: {counts}', file=sys.stderr)
            node.destroy_node()
        rclpy.try_shutdown()
    return status


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    console_main()
