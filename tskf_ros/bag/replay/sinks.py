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

"""Where a replay's outputs go: kept in memory or written to a bag (arrays: array_sink)."""

from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime, timezone
import struct
from typing import Any, Optional, Protocol

from tskf_ros.bag.cdr import serialize
from tskf_ros.bag.reader import Damage, RawMessage
from tskf_ros.bag.replay.adapters import AnyOutcome, ESTIMATE_TOPICS, OfflineEstimator
from tskf_ros.bag.replay.rts_replay import SmoothingRecorder
from tskf_ros.bag.writer import BagWriteError, BagWriter
from tskf_ros.core.units import NS
from tskf_ros.messages.estimator_interface import DIAGNOSTICS_TOPIC

__all__ = ['BagSink', 'check_stamp', 'Collector', 'LAST_STAMP_NS', 'ReplayResult', 'Sink',
           'SMOOTHED_TOPIC', 'StampRangeError']

# the RTS-smoothed estimates x(t|T) of replay_offline --smooth (the live node's fixed-lag
# smoothed topic, which has the same layout)
SMOOTHED_TOPIC = ESTIMATE_TOPICS['smoothed']
# the last instant a ROS 2 message stamp holds (builtin_interfaces/Time: int32 sec, uint32
# nanosec): 2038-01-19T03:14:07.999999999Z.  A bag's log times are int64 ns (to 2262).
LAST_STAMP_NS = (2**31 - 1) * NS + NS - 1


class StampRangeError(BagWriteError):
    """An output message whose header stamp a ROS 2 message cannot hold (after 2038)."""


def _iso(ns: int) -> str:
    """Return a time in ns since the epoch as ISO 8601 UTC, to the second."""
    return datetime.fromtimestamp(ns // NS, timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ')


def check_stamp(topic: str, stamp_ns: int) -> None:
    """Raise StampRangeError if a message on `topic` cannot be stamped at stamp_ns."""
    if not 0 <= stamp_ns <= LAST_STAMP_NS:
        way = ('replay with --no-diagnostics or to --npz (samples stamped after it are '
               'rejected as stamp_range, as the node rejects them)' if topic == DIAGNOSTICS_TOPIC
               else 'this output cannot be written for this bag')
        raise StampRangeError(
            f'{topic} at {_iso(stamp_ns)}: past {_iso(LAST_STAMP_NS)}, the last instant a ROS 2 '
            'message stamp (builtin_interfaces/Time, int32 seconds) holds, although the '
            f"bag's log times (int64 ns) reach 2262: {way}")


@dataclass
class ReplayResult:
    """What a replay did: counts, statuses, assumptions, damage, and collected outputs."""

    topic: str = ''
    msgtype: str = ''
    read: int = 0
    samples: int = 0
    written: Counter = field(default_factory=Counter)
    statuses: Counter = field(default_factory=Counter)
    assumptions: list[str] = field(default_factory=list)
    damage: Optional[Damage] = None
    seconds: float = 0.0
    outputs: list[tuple] = field(default_factory=list)  # (topic, log_ns, msg) when collecting
    input_topic: str = ''                               # the input u's topic ('' none)
    inputs: int = 0
    input_statuses: Counter = field(default_factory=Counter)


class Sink(Protocol):
    """What the replay loop hands every input message, outcome and /diagnostics message to."""

    copies: bool        # whether copy() does anything (the loop skips it if not)

    def copy(self, raw: RawMessage) -> None:
        """Take an input message as it was read."""

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Take what the session made of a measurement (is_input False) or an input u."""

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Take a /diagnostics message (rclpy) due at stamp_ns."""

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Take an rclpy message that the node publishes outside an outcome, as it starts."""


class Collector:
    """Outputs kept in memory as rclpy messages (result.outputs)."""

    copies = True

    def __init__(self, result: ReplayResult) -> None:
        self.result = result

    def copy(self, raw: RawMessage) -> None:
        """Keep the input message."""
        self.result.outputs.append((raw.topic, raw.log_time_ns, raw))

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Keep the messages the live node publishes for out."""
        for topic, msg in est.messages(out):
            self.result.written[topic] += 1
            self.result.outputs.append((topic, log_ns, msg))

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Keep the /diagnostics message."""
        self.message(DIAGNOSTICS_TOPIC, stamp_ns, msg)

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Keep the message."""
        self.result.written[topic] += 1
        self.result.outputs.append((topic, log_ns, msg))


# smoothed messages serialized and written at a time
SMOOTHED_CHUNK = 4096


class BagSink:
    """Outputs written to a bag, serialized to canonical CDR; the inputs copied as read."""

    copies = True

    def __init__(self, writer: BagWriter, result: ReplayResult,
                 smoother: Optional[SmoothingRecorder] = None) -> None:
        self.writer = writer
        self.written = result.written
        self.smoother = smoother
        self.last_log_ns = 0

    def copy(self, raw: RawMessage) -> None:
        """Write the input message's bytes as they were read (if its topic was added)."""
        if self.writer.has_topic(raw.topic):
            self.writer.write(raw.topic, raw.log_time_ns, raw.data)

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Write the messages the live node publishes for out, at the input's log time."""
        try:
            pairs = est.encoded(out)
        except struct.error:        # rosbags' serializer: a header stamp past 2038
            check_stamp(est.output_topics()[0][0], log_ns)
            raise
        written = self.written
        for topic, _ in pairs:
            written[topic] += 1
        self.writer.write_many(log_ns, pairs)
        if self.smoother is not None:
            self.smoother.outcome(out)
            self.last_log_ns = max(self.last_log_ns, log_ns)

    def finish(self, est: OfflineEstimator) -> None:
        """Write the smoothed estimates (if smoothing), logged at the last input's time."""
        if self.smoother is None:
            return
        rows, sigma = self.smoother.smoothed_rows()
        enc = est.encoder()
        self.written[SMOOTHED_TOPIC] += 0
        # mu of each point's step (to the next point of its segment); written a chunk of
        # messages at a time
        for a in range(0, rows.stamp_ns.size, SMOOTHED_CHUNK):
            b = a + SMOOTHED_CHUNK
            pairs = [(SMOOTHED_TOPIC, enc.estimate('smoothed', t, (s - t) / NS, x, P))
                     for t, s, x, P in zip(rows.stamp_ns[a:b].tolist(),
                                           sigma[a:b].tolist(), rows.x[a:b], rows.P[a:b])]
            self.written[SMOOTHED_TOPIC] += len(pairs)
            self.writer.write_many(self.last_log_ns, pairs)

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Write the /diagnostics message."""
        self.message(DIAGNOSTICS_TOPIC, stamp_ns, msg)

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Write the message, serialized to canonical CDR."""
        check_stamp(topic, log_ns)
        self.written[topic] += 1
        self.writer.write(topic, log_ns, serialize(msg))
