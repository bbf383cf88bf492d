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

"""record: write topics to a rosbag2 MCAP bag, with `ros2 bag record`'s (Jazzy) options."""

from pathlib import Path
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

from tskf_ros.bag.bag_options import seconds_ns, TopicFilter
from tskf_ros.bag.message_types import BagTypeError, message_class, qos_from_rclpy
from tskf_ros.bag.reader import BagError
from tskf_ros.bag.record_options import (build_parser, check_options, default_output,
                                         FLUSH_INTERVAL, NODE_NAME, recorder_options)
from tskf_ros.bag.split_bag import SplitBagWriter
from tskf_ros.bag.writer import BagWriteError, BagWriter
from tskf_ros.messages.context import end_context

# not recorded by --all unless named
INTERNAL_TOPICS = ('/rosout', '/parameter_events')
# s: after a stop signal, keep taking delivered messages for at most this long
DRAIN_LIMIT = 2.0


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
        # every number is checked before anything is made (1e308 s is refused, not an overflow)
        seconds_ns('--flush-interval', flush_interval)
        seconds_ns('--polling-interval', discovery_period, above=True)
        split_ns = seconds_ns('--max-bag-duration', max_bag_duration)
        if max_bag_size or split_ns:
            self.writer = SplitBagWriter(output, overwrite=overwrite, compress=compress,
                                         max_bytes=int(max_bag_size), max_duration_ns=split_ns)
        else:
            self.writer = BagWriter(output, overwrite=overwrite, compress=compress)
        self.writer.open()
        try:
            self._start(output, topics, types, discovery_period, flush_interval, topic_filter,
                        qos_overrides, discovery, custom_data)
        except BaseException:
            self.writer.abort()         # no .partial directory is left behind
            raise

    def _start(self, output: Path, topics: Optional[Sequence[str]], types: Optional[dict],
               discovery_period: float, flush_interval: float,
               topic_filter: Optional[TopicFilter], qos_overrides: Optional[dict],
               discovery: bool, custom_data: Optional[dict]) -> None:
        """Set the recorder up on the opened bag: timers, topics, the first discovery."""
        for key, value in (custom_data or {}).items():
            self.writer.set_custom_data(key, value)
        self.failed: Optional[BagWriteError] = None     # a write failed: stop recording
        self.flusher = (self.create_timer(flush_interval, self.flush) if flush_interval > 0
                        else None)
        self.everything = topics is None and topic_filter is None
        self.filter = topic_filter if topic_filter is not None else TopicFilter(
            topics=list(topics or []) + list(types or {}))
        self.named = set(self.filter.topics) | set(types or {})
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
        end_context()
    return status


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
