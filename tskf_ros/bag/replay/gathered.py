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

"""A bag's measurements gathered, taken by the session in runs, handed on in storage order."""

from collections import Counter
from typing import Callable, Union

import numpy as np

from tskf_ros.bag.reader import RawMessage
from tskf_ros.bag.replay.adapters import OfflineEstimator, Sample
from tskf_ros.bag.replay.array_sink import ArraySink
from tskf_ros.bag.replay.sinks import Sink
from tskf_ros.owc.session import Outcome
from tskf_ros.owc.session.outcome import Run

__all__ = ['GATHER', 'Gathered']

# messages gathered at most before they are handed over (a bound on the memory held)
GATHER = 4096


class Gathered:
    """The measurements read since the last hand-over, and the messages to copy among them."""

    def __init__(self, read_sample: Callable[[bytes, int], Sample]) -> None:
        self.read_sample = read_sample
        self.held: list[tuple[RawMessage, bool]] = []   # (message, is a measurement) to copy
        self.sampled: list[Sample] = []
        self.logs: list[int] = []
        self.samples = 0        # measurements decoded in all

    def add(self, raw: RawMessage, measurement: bool, hold: bool) -> None:
        """Take a message read: decode it if it is a measurement, hold it if it is copied."""
        if measurement:
            try:
                sample = self.read_sample(raw.data, raw.log_time_ns)
            except Exception:
                if hold:            # copied before the damage is reported
                    self.held.append((raw, False))
                raise
            self.sampled.append(sample)
            self.logs.append(raw.log_time_ns)
            self.samples += 1
        if hold:
            self.held.append((raw, measurement))

    def hand_over(self, est: OfflineEstimator, sink: Sink, statuses: Counter) -> None:
        """Run the measurements through est's session; give the sink everything, in order."""
        sampled, logs = self.sampled, self.logs
        items: list[Union[Run, Outcome]] = []
        if sampled:
            columns = zip(*sampled)
            stamps = np.array(next(columns), dtype=np.int64)
            values = np.array(next(columns), dtype=float)
            variances = np.array(next(columns), dtype=float)
            log_array = np.array(logs, dtype=np.int64)
            items = est.session.add_many(stamps, values, variances, log_array)
        rows = isinstance(sink, ArraySink) and sink.smoother is None and not self.held
        outcomes: list[Outcome] = []
        k = 0
        for item in items:
            if not isinstance(item, Run):
                if rows:
                    sink.outcome(est, logs[k], sampled[k], item, False)
                    k += 1
                else:
                    outcomes.append(item)
                statuses[item.status] += 1
                continue
            statuses['accepted'] += item.count
            if rows:
                end = k + item.count
                sink.run_rows(item, log_array[k:end], stamps[k:end], values[k:end],
                              variances[k:end])
                k = end
            else:
                outcomes += item.outcomes()
        if not rows:
            k = 0
            for raw, measurement in self.held:
                sink.copy(raw)
                if measurement:
                    sink.outcome(est, logs[k], sampled[k], outcomes[k], False)
                    k += 1
            for j in range(k, len(outcomes)):       # a sink that copies nothing
                sink.outcome(est, logs[j], sampled[j], outcomes[j], False)
        self.held, self.sampled, self.logs = [], [], []
