"""record: write topics to a rosbag2 MCAP bag, with `ros2 bag record`'s (Jazzy) options."""

import argparse
import datetime
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
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from tskf_ros.bag.bag_options import (compile_regex, load_qos_overrides, OptionError,
                                      STORAGE_ID, TopicFilter)
from tskf_ros.bag.message_types import BagTypeError, message_class, qos_from_rclpy
from tskf_ros.bag.reader import BagError
from tskf_ros.bag.split_bag import SplitBagWriter
from tskf_ros.bag.writer import BagWriteError, BagWriter
from tskf_ros.core.units import NS

EPILOG = """examples:
  record --topics /received_power /true_angle -o /tmp/run1
  record -a -o /tmp/run1 --exclude-regex '^/estimate' -b 50000000
  record --topics /received_power:sensor_msgs/msg/Illuminance   # type given, no wait

The bag is written into a hidden .partial directory and renamed when closed.  Every
--flush-interval s the chunk in progress is written and fsynced: after a SIGKILL or a power
loss, `reindex` makes a bag of the .partial directory.  A full disk stops the recording;
what reached the disk is closed as a valid bag and the command exits 1."""

NODE_NAME = 'recorder'
# not recorded by --all unless named
INTERNAL_TOPICS = ('/rosout', '/parameter_events')
# a fully qualified topic name (rcl's grammar, without substitutions)
TOPIC_NAME = re.compile(r'/|(/[A-Za-z_][A-Za-z0-9_]*)+')
# s: after a stop signal, keep taking delivered messages for at most this long
DRAIN_LIMIT = 2.0
# s: default interval between flushes (what a SIGKILL or a power loss may lose at most)
FLUSH_INTERVAL = 1.0
# rosbag2's default bag name: the local date and time
DEFAULT_NAME_FORMAT = 'rosbag2_%Y_%m_%d-%H_%M_%S'
# --storage-preset-profile of rosbag2's MCAP plugin -> zstd chunk compression here
PRESET_COMPRESS = {'none': False, 'zstd_fast': True, 'zstd_small': True}


def hidden(topic: str) -> bool:
    """Say whether a topic is hidden: a token of its name starts with an underscore."""
    return any(token.startswith('_') for token in topic.split('/'))


class Recorder(Node):
    """
    Record topics to a bag; `close()` finishes the bag.

    topics: names to record (None: all but INTERNAL_TOPICS and hidden topics), or
    topic_filter for regular expressions and exclusions; types: name -> type for topics to
    subscribe without waiting for the graph; qos_overrides: name -> subscription QoS;
    max_bag_size (bytes) / max_bag_duration (s): split the bag (SplitBagWriter).
    """

    def __init__(self, output: Path, *, topics: Optional[Sequence[str]] = None,
                 types: Optional[dict] = None, overwrite: bool = False,
                 compress: bool = False, discovery_period: float = 0.2,
                 flush_interval: float = FLUSH_INTERVAL,
                 topic_filter: Optional[TopicFilter] = None,
                 qos_overrides: Optional[dict] = None, max_bag_size: int = 0,
                 max_bag_duration: float = 0.0, discovery: bool = True,
                 custom_data: Optional[dict] = None, context=None,
                 node_name: str = NODE_NAME,
                 parameter_overrides: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, parameter_overrides=parameter_overrides)
        if not (math.isfinite(flush_interval) and flush_interval >= 0):
            raise BagWriteError(f'flush interval must be a finite number >= 0, got '
                                f'{flush_interval}')
        if max_bag_size or max_bag_duration:
            self.writer = SplitBagWriter(output, overwrite=overwrite, compress=compress,
                                         max_bytes=int(max_bag_size),
                                         max_duration_ns=int(round(max_bag_duration * NS)))
        else:
            self.writer = BagWriter(output, overwrite=overwrite, compress=compress)
        self.writer.open()
        for key, value in (custom_data or {}).items():
            self.writer.set_custom_data(key, value)
        self.failed: Optional[BagWriteError] = None     # a write failed: stop recording
        self.flusher = (self.create_timer(flush_interval, self.flush) if flush_interval > 0
                        else None)
        self.everything = topics is None and topic_filter is None
        self.filter = topic_filter if topic_filter is not None else TopicFilter(
            topics=list(topics or []) + list(types or {}))
        self.named = set(self.filter.topics)
        self.qos_overrides = dict(qos_overrides or {})
        self.sim_time = self.get_parameter('use_sim_time').value
        self.before_clock = 0           # messages not written: no /clock yet (sim time)
        self.counts: dict[str, int] = {}
        self.subs: dict = {}
        for topic, msgtype in (types or {}).items():
            self._subscribe(topic, msgtype)
        self.discovery = self.create_timer(discovery_period, self.discover)
        self.discover()
        if not discovery:
            self.discovery.cancel()
        what = 'all topics' if self.everything else ', '.join(sorted(self.named)) or 'topics'
        self.get_logger().info(f'recording {what} to {output}')

    def wanted(self, topic: str) -> bool:
        """Say whether a topic of the graph is to be recorded."""
        if topic in self.named:
            return True
        if topic in INTERNAL_TOPICS or hidden(topic):
            return False
        return self.everything or self.filter.take(topic)

    def discover(self) -> None:
        """Subscribe to wanted topics that have appeared in the graph."""
        for topic, msgtypes in self.get_topic_names_and_types():
            if topic in self.subs or not self.wanted(topic):
                continue
            if len(msgtypes) != 1:
                self.get_logger().warning(f'{topic} has several types {msgtypes}; skipped')
                self.subs[topic] = None
                continue
            if not self.get_publishers_info_by_topic(topic):
                continue
            self._subscribe(topic, msgtypes[0])

    def _qos(self, topic: str, offered: list) -> QoSProfile:
        """Return the subscription's QoS: the override, else compatible with every publisher."""
        if topic in self.qos_overrides:
            return self.qos_overrides[topic]
        reliable = bool(offered) and all(
            p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
        latched = bool(offered) and all(
            p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
        return QoSProfile(
            history=HistoryPolicy.KEEP_ALL, depth=1000,
            reliability=ReliabilityPolicy.RELIABLE if reliable
            else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
            else DurabilityPolicy.VOLATILE)

    def _subscribe(self, topic: str, msgtype: str) -> None:
        try:
            cls = message_class(msgtype)
        except BagTypeError as exc:
            self.get_logger().error(f'{topic}: {exc}; not recorded')
            self.subs[topic] = None
            return
        if self.writer is None or self.failed is not None:
            return
        offered = [i.qos_profile for i in self.get_publishers_info_by_topic(topic)]
        qos = self._qos(topic, offered)
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
        sim_time = self.sim_time

        def on_message(data: bytes) -> None:
            if self.failed is not None:
                return
            now = clock.now().nanoseconds
            if sim_time and now == 0:
                self.before_clock += 1          # rosbag2: nothing before the first /clock
                return
            try:
                write(topic, now, data)
            except BagWriteError as exc:
                self._fail(exc)
                return
            self.counts[topic] += 1
        self.subs[topic] = self.create_subscription(cls, topic, on_message, qos, raw=True)
        self.get_logger().info(f'subscribed to {topic} ({msgtype}, '
                               f'{qos.reliability.name.lower().replace("_", " ")})')

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


def build_parser() -> argparse.ArgumentParser:
    """Return the command line: the spelling, defaults and short options of Jazzy's."""
    parser = argparse.ArgumentParser(
        prog='record', description='Record topics to a rosbag2 MCAP bag (raw, receive time '
        'as log time), with the options of ros2 bag record (Jazzy).', epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('-o', '--output', type=Path,
                        help='bag directory to create (default: rosbag2_YYYY_MM_DD-HH_MM_SS '
                        'in the current directory, from the local date and time)')
    parser.add_argument('-s', '--storage', default=STORAGE_ID, choices=['mcap', 'sqlite3'],
                        help='storage (mcap only: sqlite3 is refused)')
    topics = parser.add_mutually_exclusive_group()
    topics.add_argument('topics_positional', nargs='*', default=[], metavar='[Topic ...]',
                        help='topics to record (deprecated, as in Jazzy: use --topics)')
    topics.add_argument('--topics', nargs='+', default=[], metavar='Topic',
                        help='topics to record: NAME, or NAME:TYPE to subscribe without '
                        'waiting for a publisher (our extra)')
    parser.add_argument('-a', '--all', action='store_true',
                        help='record every topic, discovered as it appears (but hidden '
                        'topics, /rosout and /parameter_events)')
    parser.add_argument('-e', '--regex', default='',
                        help='record the topics whose name contains a match of this regular '
                        'expression (--all overrides it)')
    parser.add_argument('--exclude-regex', default='',
                        help='do not record topics containing a match (on top of --all or '
                        '--regex)')
    parser.add_argument('--exclude-topics', nargs='+', default=[], metavar='Topic',
                        help='topics not to record (on top of --all or --regex)')
    parser.add_argument('--no-discovery', action='store_true',
                        help='record only the topics present at startup')
    parser.add_argument('-p', '--polling-interval', type=int, default=100, metavar='MS',
                        help='ms between looks at the graph for new topics (default 100)')
    parser.add_argument('--qos-profile-overrides-path', type=Path, metavar='YAML',
                        help="subscription QoS per topic (rosbag2's YAML format)")
    parser.add_argument('-b', '--max-bag-size', type=int, default=0, metavar='BYTES',
                        help='split the bag into files of this many bytes of messages '
                        '(0: one file)')
    parser.add_argument('-d', '--max-bag-duration', type=int, default=0, metavar='S',
                        help='split the bag into files of this many seconds (0: one file; '
                        'with -b, whichever is reached first)')
    parser.add_argument('--compression-mode', default='none',
                        choices=['none', 'file', 'message'],
                        help='file or message: zstd-compress the MCAP chunks (what each '
                        'means here: README)')
    parser.add_argument('--compression-format', default='', choices=['zstd'],
                        help='zstd (the only one, as in Jazzy); needs --compression-mode')
    parser.add_argument('--storage-preset-profile', default='none',
                        choices=sorted(PRESET_COMPRESS),
                        help='zstd_fast, zstd_small: zstd chunk compression')
    parser.add_argument('--use-sim-time', action='store_true',
                        help='log times from /clock; nothing is written before the first')
    parser.add_argument('--node-name', default=NODE_NAME, help='the recorder node name')
    parser.add_argument('--custom-data', nargs='*', default=[], metavar='KEY=VALUE',
                        help="entries of metadata.yaml's custom_data")
    parser.add_argument('--overwrite', action='store_true',
                        help='replace an existing bag written by tskf_ros (our extra)')
    parser.add_argument('--flush-interval', type=float, default=FLUSH_INTERVAL, metavar='S',
                        help='write and fsync the chunk in progress every S seconds: what a '
                        f'crash may lose at most (default {FLUSH_INTERVAL:g}; 0: only when '
                        'chunks fill; our extra)')
    return parser


def check_options(parser: argparse.ArgumentParser, opts: argparse.Namespace) -> None:
    """Refuse bad combinations and values (argparse's usage error, exit 2) as rosbag2 does."""
    if opts.topics_positional:
        print('[WARN] [record]: positional topics are deprecated (as in ros2 bag record); '
              'use --topics', file=sys.stderr)
        opts.topics = opts.topics_positional
    for given, flag in ((opts.topics, '--topics'), (opts.regex, '--regex')):
        if opts.all and given:
            print(f'[WARN] [record]: --all overrides {flag} (as in ros2 bag record)',
                  file=sys.stderr)
    if not (opts.all or opts.topics or opts.regex):
        parser.error('need --all, --topics or --regex')
    if opts.exclude_regex and not (opts.all or opts.regex):
        parser.error('--exclude-regex needs --all or --regex')
    if opts.exclude_topics and not (opts.all or opts.regex):
        parser.error('--exclude-topics needs --all or --regex')
    if opts.compression_format and opts.compression_mode == 'none':
        parser.error('--compression-format needs --compression-mode file or message')
    for flag, value in (('--max-bag-size', opts.max_bag_size),
                        ('--max-bag-duration', opts.max_bag_duration)):
        if value < 0:
            parser.error(f'{flag} must be >= 0, got {value}')
    if opts.polling_interval <= 0:
        parser.error(f'--polling-interval must be > 0, got {opts.polling_interval}')
    if not (math.isfinite(opts.flush_interval) and opts.flush_interval >= 0):
        parser.error(f'--flush-interval must be a finite number >= 0, got '
                     f'{opts.flush_interval}')
    names, types = parse_topics(opts.topics + opts.exclude_topics)
    bad = [n for n in names + list(types) if not TOPIC_NAME.fullmatch(n)]
    if bad:
        parser.error(f'not a topic name: {bad[0]}')
    for pair in opts.custom_data:
        if '=' not in pair or not pair.partition('=')[0]:
            parser.error(f'--custom-data: expected KEY=VALUE, got {pair!r}')


def recorder_options(opts: argparse.Namespace) -> dict:
    """Return the Recorder's keyword arguments for parsed options (raises OptionError)."""
    if opts.storage != STORAGE_ID:
        raise OptionError(f'--storage {opts.storage}: this recorder writes mcap only')
    names, types = parse_topics(opts.topics)
    topic_filter = TopicFilter(topics=[] if opts.all else names,
                               regex=None if opts.all else compile_regex('--regex', opts.regex),
                               exclude_topics=parse_topics(opts.exclude_topics)[0],
                               exclude_regex=compile_regex('--exclude-regex',
                                                           opts.exclude_regex))
    everything = opts.all and not opts.exclude_topics and not opts.exclude_regex
    return {
        'topics': None if everything else names, 'types': {} if opts.all else types,
        'topic_filter': None if everything else topic_filter,
        'overwrite': opts.overwrite,
        'compress': (opts.compression_mode != 'none'
                     or PRESET_COMPRESS[opts.storage_preset_profile]),
        'discovery_period': opts.polling_interval / 1000.0,
        'discovery': not opts.no_discovery,
        'flush_interval': opts.flush_interval,
        'qos_overrides': load_qos_overrides(opts.qos_profile_overrides_path),
        'max_bag_size': opts.max_bag_size, 'max_bag_duration': float(opts.max_bag_duration),
        'custom_data': dict(pair.split('=', 1) for pair in opts.custom_data),
        'node_name': opts.node_name,
        'parameter_overrides': ([Parameter('use_sim_time', value=True)]
                                if opts.use_sim_time else None)}


def default_output(now: Optional[datetime.datetime] = None) -> Path:
    """Return rosbag2's default bag name, from the local date and time."""
    return Path((now or datetime.datetime.now()).strftime(DEFAULT_NAME_FORMAT))


def main(args: Optional[list] = None) -> int:
    """Record until Ctrl-C or SIGTERM; return the exit status."""
    argv = remove_ros_args(sys.argv if args is None else args)[1:]
    parser = build_parser()
    opts = parser.parse_args(argv)
    check_options(parser, opts)
    output = opts.output if opts.output is not None else default_output()
    try:
        kwargs = recorder_options(opts)
        BagWriter(output, overwrite=opts.overwrite).check_target()
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
        node = Recorder(output, **kwargs)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
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
