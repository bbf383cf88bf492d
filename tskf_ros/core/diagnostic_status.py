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

"""
diagnostic_updater's status wrapper, FrequencyStatus and TimeStampStatus, without ROS.

As ros/diagnostics' diagnostic_updater (ros2-jazzy, _update_functions.py and
update_functions.hpp), on the receiver clock in ns handed in:

    FrequencyStatus:  f = events / window over the last window_size updates;
        ERROR 'No events recorded.' (events = 0), WARN 'Frequency too low.'
        (f < min (1 - tolerance)), WARN 'Frequency too high.' (f > max (1 + tolerance)),
        else OK 'Desired frequency met'
    TimeStampStatus:  delay = now - stamp of each event since the last update;
        ERROR 'Timestamps too far in future seen.' (min delay < min_acceptable),
        'Timestamps too far in past seen.' (max delay > max_acceptable), 'Zero timestamp
        seen.'; WARN 'No data since last update.'; else OK 'Timestamps are reasonable.'
"""

from dataclasses import dataclass, field
import math
from typing import NamedTuple, Optional, Union

from tskf_ros.core.units import NS

# DiagnosticStatus's levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = ('OK', 'WARN', 'ERROR', 'STALE')
# the task names the two filtering sessions share
INPUT_FREQUENCY, TIMESTAMP_DELAY, TIME_SCALE = 'input frequency', 'timestamp delay', 'time scale'
# a key's value before it is printed: a count, a measurement or a text
Value = Union[int, float, str]


class KeyValue(NamedTuple):
    """One key value of a status (diagnostic_msgs/KeyValue), the value printed."""

    key: str
    value: str


def printed(value: Value) -> str:
    """Return a value as a status shows it: floats at full precision (repr), else str."""
    return repr(value) if isinstance(value, float) else str(value)


@dataclass
class Status:
    """A task's status as diagnostic_updater's DiagnosticStatusWrapper fills it."""

    name: str
    level: int = ERROR                   # as the Updater starts every task's status
    message: str = 'No message was set'
    values: list[KeyValue] = field(default_factory=list)

    def summary(self, level: int, message: str) -> None:
        """Set the level and the message."""
        self.level, self.message = level, message

    def merge_summary(self, level: int, message: str) -> None:
        """Merge a level and message in, as DiagnosticStatusWrapper.mergeSummary does."""
        if (level > OK) == (self.level > OK):
            if self.message:
                self.message += '; '
            self.message += message
        elif level > self.level:
            self.message = message
        self.level = max(self.level, level)

    def add(self, key: str, value: Value) -> None:
        """Add a key value (a float at full precision)."""
        self.values.append(KeyValue(key, printed(value)))

    def as_dict(self) -> dict[str, str]:
        """Return the key values as a dict."""
        return dict(self.values)


@dataclass(frozen=True)
class FrequencyParams:
    """FrequencyStatusParam: bounds (Hz, max may be inf), tolerance, updates in the window."""

    min_freq: float
    max_freq: float
    tolerance: float = 0.1
    window_size: int = 5


def expected_frequency(expected_rate: float, tolerance: float,
                       period: float) -> FrequencyParams:
    """Return the params of a stream expected at expected_rate Hz (0: 1 / period)."""
    rate = expected_rate if expected_rate > 0 else 1.0 / period
    return FrequencyParams(rate, rate, tolerance)


class FrequencyStatus:
    """Events counted by tick(), judged at each run() over the last window_size runs."""

    def __init__(self, params: FrequencyParams, now_ns: Optional[int] = None) -> None:
        self.params = params
        self.count = 0
        self.times: list[int] = []       # of the last window_size runs; []: not started
        if now_ns is not None:
            self.clear(now_ns)

    def clear(self, now_ns: int) -> None:
        """Reset the statistics; the first window starts at now_ns."""
        self.count = 0
        self.times = []
        self.start(now_ns)

    def start(self, now_ns: int) -> None:
        """Start the first window at now_ns, if it has not started (events counted stay)."""
        if self.times:
            return
        n = max(1, int(self.params.window_size))
        self.times = [int(now_ns)] * n
        self.seq_nums = [0] * n
        self.hist_indx = 0

    def tick(self) -> None:
        """Count one event."""
        self.count += 1

    def run(self, stat: Status, now_ns: int) -> Status:
        """Fill stat with the level, message and keys of FrequencyStatus.run."""
        if not self.times:
            self.start(now_ns)
        p, i = self.params, self.hist_indx
        events = self.count - self.seq_nums[i]
        window = (int(now_ns) - self.times[i]) / NS
        freq = events / window if window > 0 else (math.inf if events else 0.0)
        self.seq_nums[i], self.times[i] = self.count, int(now_ns)
        self.hist_indx = (i + 1) % len(self.times)
        if events == 0:
            stat.summary(ERROR, 'No events recorded.')
        elif freq < p.min_freq * (1 - p.tolerance):
            stat.summary(WARN, 'Frequency too low.')
        elif freq > p.max_freq * (1 + p.tolerance):
            stat.summary(WARN, 'Frequency too high.')
        else:
            stat.summary(OK, 'Desired frequency met')
        stat.values += [KeyValue('Events in window', '%d' % events),
                        KeyValue('Events since startup', '%d' % self.count),
                        KeyValue('Duration of window (s)', '%f' % window),
                        KeyValue('Actual frequency (Hz)', '%f' % freq)]
        if p.min_freq == p.max_freq:
            stat.values.append(KeyValue('Target frequency (Hz)', '%f' % p.min_freq))
        if p.min_freq > 0:
            stat.values.append(KeyValue('Minimum acceptable frequency (Hz)',
                                        '%f' % (p.min_freq * (1 - p.tolerance))))
        if math.isfinite(p.max_freq):
            stat.values.append(KeyValue('Maximum acceptable frequency (Hz)',
                                        '%f' % (p.max_freq * (1 + p.tolerance))))
        return stat


@dataclass(frozen=True)
class TimeStampParams:
    """TimeStampStatusParam: the acceptable delays now - stamp (s)."""

    min_acceptable: float = -1.0
    max_acceptable: float = 5.0


class TimeStampStatus:
    """The delays of the stamps seen by tick() since the last run(), judged at each run()."""

    def __init__(self, params: TimeStampParams) -> None:
        self.params = params
        self.early_count = self.late_count = self.zero_count = 0
        self._since_update()

    def _since_update(self) -> None:
        self.zero_seen = False
        self.deltas_valid = False
        self.min_delta = self.max_delta = 0.0

    def tick(self, stamp_ns: int, now_ns: int) -> None:
        """Note one event stamped stamp_ns, received at now_ns (0: a zero stamp)."""
        if stamp_ns == 0:
            self.zero_seen = True
            return
        delta = (now_ns - stamp_ns) / NS
        if not self.deltas_valid:
            self.min_delta = self.max_delta = delta
            self.deltas_valid = True
        elif delta > self.max_delta:
            self.max_delta = delta
        elif delta < self.min_delta:
            self.min_delta = delta

    def tick_many(self, stamps_ns: list[int], nows_ns: list[int]) -> None:
        """Note events in order, as tick() one at a time: the delays' running min and max."""
        if 0 in stamps_ns:
            for stamp_ns, now_ns in zip(stamps_ns, nows_ns):
                self.tick(stamp_ns, now_ns)
            return
        deltas = [(now_ns - stamp_ns) / NS for stamp_ns, now_ns in zip(stamps_ns, nows_ns)]
        if not deltas:
            return
        if not self.deltas_valid:
            self.min_delta = self.max_delta = deltas[0]
            self.deltas_valid = True
        self.min_delta = min(self.min_delta, min(deltas))
        self.max_delta = max(self.max_delta, max(deltas))

    def run(self, stat: Status) -> Status:
        """Fill stat with the level, message and keys of TimeStampStatus.run."""
        p = self.params
        stat.summary(OK, 'Timestamps are reasonable.')
        if not self.deltas_valid:
            stat.summary(WARN, 'No data since last update.')
        else:
            if self.min_delta < p.min_acceptable:
                stat.summary(ERROR, 'Timestamps too far in future seen.')
                self.early_count += 1
            if self.max_delta > p.max_acceptable:
                stat.summary(ERROR, 'Timestamps too far in past seen.')
                self.late_count += 1
            if self.zero_seen:
                stat.summary(ERROR, 'Zero timestamp seen.')
                self.zero_count += 1
        stat.values += [
            KeyValue('Earliest timestamp delay:', '%f' % self.min_delta),
            KeyValue('Latest timestamp delay:', '%f' % self.max_delta),
            KeyValue('Earliest acceptable timestamp delay:', '%f' % p.min_acceptable),
            KeyValue('Latest acceptable timestamp delay:', '%f' % p.max_acceptable),
            KeyValue('Late diagnostic update count:', '%i' % self.late_count),
            KeyValue('Early diagnostic update count:', '%i' % self.early_count),
            KeyValue('Zero seen diagnostic update count:', '%i' % self.zero_count)]
        self._since_update()
        return stat


class InputStream:
    """The two tasks of an input topic, as TopicDiagnostic: its frequency and its stamps."""

    def __init__(self, frequency: FrequencyParams,
                 stamps: TimeStampParams = TimeStampParams()) -> None:
        self.frequency = FrequencyStatus(frequency)
        self.stamps = TimeStampStatus(stamps)

    def note(self, stamp_ns: int, now_ns: int) -> None:
        """Count one message stamped stamp_ns received at now_ns (receiver clock)."""
        frequency = self.frequency
        if not frequency.times:
            frequency.start(now_ns)
        frequency.count += 1
        self.stamps.tick(stamp_ns, now_ns)

    def note_many(self, stamps_ns: list[int], nows_ns: list[int]) -> None:
        """Count messages in order, as note() one at a time."""
        if not stamps_ns:
            return
        frequency = self.frequency
        if not frequency.times:
            frequency.start(nows_ns[0])
        frequency.count += len(stamps_ns)
        self.stamps.tick_many(stamps_ns, nows_ns)

    def run(self, now_ns: int) -> list[Status]:
        """Return the statuses 'input frequency' and 'timestamp delay' at now_ns."""
        return [self.frequency.run(Status(INPUT_FREQUENCY), now_ns),
                self.stamps.run(Status(TIMESTAMP_DELAY))]

    def configure(self, frequency: FrequencyParams) -> None:
        """Judge the frequency against new params from now on (the counts stay)."""
        self.frequency.params = frequency
