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
from typing import Any, Callable, Union

import numpy as np
from numpy.typing import NDArray

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
        # (stamps, values, variances, log times) taken before, in order: blocks and the
        # samples of `sampled` settled into arrays when a block came after them
        self.parts: list[tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64],
                               NDArray[np.int64]]] = []
        self.pending = 0        # measurements gathered since the last hand-over
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
            self.pending += 1
        if hold:
            self.held.append((raw, measurement))

    def add_block(self, stamps: NDArray[np.int64], values: NDArray[np.float64],
                  variances: NDArray[np.float64], logs: NDArray[np.int64]) -> None:
        """Take measurements decoded at once (a MessageBlock's rows), after those taken."""
        self._settle()
        self.parts.append((stamps, values, variances, logs))
        self.samples += len(logs)
        self.pending += len(logs)

    def _settle(self) -> None:
        """Move the samples taken one by one into `parts`, as arrays."""
        if self.sampled:
            columns = zip(*self.sampled)
            self.parts.append((np.array(next(columns), dtype=np.int64),
                               np.array(next(columns), dtype=float),
                               np.array(next(columns), dtype=float),
                               np.array(self.logs, dtype=np.int64)))
            self.sampled, self.logs = [], []

    def hand_over(self, est: OfflineEstimator, sink: Sink, statuses: Counter) -> None:
        """Run the measurements through est's session; give the sink everything, in order."""
        self._settle()
        parts = self.parts
        items: list[Union[Run, Outcome]] = []
        logs: Any = ()
        if parts:
            stamps, values, variances, log_array = (
                parts[0] if len(parts) == 1 else
                tuple(np.concatenate(c) for c in zip(*parts)))
            items = est.session.add_many(stamps, values, variances, log_array)
            logs = log_array

            def sampled(k: int) -> Sample:
                return int(stamps[k]), float(values[k]), float(variances[k])
        rows = isinstance(sink, ArraySink) and sink.smoother is None and not self.held
        outcomes: list[Outcome] = []
        k = 0
        for item in items:
            if not isinstance(item, Run):
                if rows:
                    sink.outcome(est, int(logs[k]), sampled(k), item, False)
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
                    sink.outcome(est, int(logs[k]), sampled(k), outcomes[k], False)
                    k += 1
            for j in range(k, len(outcomes)):       # a sink that copies nothing
                sink.outcome(est, int(logs[j]), sampled(j), outcomes[j], False)
        self.held, self.parts, self.pending = [], [], 0
