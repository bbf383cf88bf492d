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
What `innovation_trace.run_stream` keeps of a session's run, as columns, in bounded memory.

The session revises its newest points when a late sample is inserted, so the collector
keeps the points a late sample may still revise (a few times the session's history_size)
by (segment, stamp), and makes the older ones final: rows of float64 columns grown in
place, oldest first (segment, then stamp), as the dicts sorted at the end would give:

- TraceColumns: the filter steps (mu, y, u, the sample's variance), segment by segment,
  read back as `StepRecord`s one at a time (a Sequence of segments, each a Sequence of
  records, as `noise_fit` takes): 8 (2 + p + m) + 2 bytes a step;
- the innovation e_k and S_k of each measurement step: 8 (p + p^2) bytes;
- EstimateColumns: the final corrected x(t|t) and predicted xhat(t) at each stamp (only
  if asked for: the sweep's truth errors): 8 (2 + 2 n) + 2 bytes a stamp.

No ROS, no I/O.
"""

from typing import Iterator, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.growing_column import Column
from tskf_ros.core.noise_fit import StepRecord

__all__ = ['EstimateColumns', 'TraceColumns']

FloatArray = NDArray[np.float64]


class _OptionalRows:
    """A column of arrays, some rows absent (None), the width set by the first present."""

    def __init__(self) -> None:
        self.present = Column(np.int8)
        self.values: Optional[Column] = None
        self.missing = 0            # rows absent before the first present one

    def append(self, value: Optional[FloatArray]) -> None:
        self.present.append(value is not None)
        if value is None:
            if self.values is None:
                self.missing += 1
            else:
                self.values.append(np.nan)
            return
        if self.values is None:
            shape = np.shape(value)
            self.values = Column(np.float64, shape)
            for _ in range(self.missing):
                self.values.append(np.nan)
        self.values.append(value)

    def get(self, k: int) -> Optional[FloatArray]:
        if self.values is None or not self.present.data[k]:
            return None
        return self.values.data[k].copy()


class _SegmentView(Sequence[StepRecord]):
    """Rows start..end-1 of a TraceColumns as StepRecords (made when read)."""

    def __init__(self, trace: 'TraceColumns', start: int, end: int) -> None:
        self.trace, self.start, self.end = trace, start, end

    def __len__(self) -> int:
        return self.end - self.start

    def __getitem__(self, i):  # int or slice, as a Sequence
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        if not -len(self) <= i < len(self):
            raise IndexError(i)
        return self.trace.record(self.start + i % len(self))

    def __iter__(self) -> Iterator[StepRecord]:
        record = self.trace.record
        return (record(k) for k in range(self.start, self.end))


class TraceColumns(Sequence[Sequence[StepRecord]]):
    """The filter steps of a run, segment by segment, as columns."""

    def __init__(self) -> None:
        self.mu = Column(np.float64)
        self.variance = Column(np.float64)
        self.y = _OptionalRows()
        self.u = _OptionalRows()
        self.starts: list[int] = []     # first row of each segment
        self.segment: Optional[int] = None

    def append(self, segment: int, rec: StepRecord) -> None:
        """Add a step of `segment` (segments in order, each step after the previous)."""
        if segment != self.segment:
            self.starts.append(self.mu.count)
            self.segment = segment
        self.mu.append(rec.mu)
        self.variance.append(rec.variance)
        self.y.append(None if rec.y is None else np.asarray(rec.y, dtype=float))
        self.u.append(None if rec.u is None else np.asarray(rec.u, dtype=float))

    def record(self, k: int) -> StepRecord:
        """Return step k (counted over all segments)."""
        return StepRecord(mu=float(self.mu.data[k]), y=self.y.get(k), u=self.u.get(k),
                          variance=float(self.variance.data[k]))

    @property
    def steps(self) -> int:
        """Return the number of steps over all segments."""
        return self.mu.count

    def __len__(self) -> int:
        return len(self.starts)

    def __getitem__(self, i):  # int or slice, as a Sequence
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        i = range(len(self))[i]
        ends = self.starts[1:] + [self.mu.count]
        return _SegmentView(self, self.starts[i], ends[i])


class EstimateColumns:
    """The final corrected and predicted estimate at each (segment, stamp), oldest first."""

    def __init__(self) -> None:
        self.segment = Column(np.int64)
        self.stamp = Column(np.int64)
        self.corrected = _OptionalRows()
        self.predicted = _OptionalRows()

    def append(self, segment: int, stamp_ns: int, corrected: Optional[FloatArray],
               predicted: Optional[FloatArray]) -> None:
        """Add the estimates at a point (None: none of that kind)."""
        self.segment.append(segment)
        self.stamp.append(stamp_ns)
        self.corrected.append(corrected)
        self.predicted.append(predicted)

    def rows(self, kind: str) -> tuple[NDArray[np.int64], FloatArray]:
        """Return (stamps, x) of the points with an estimate of kind 'corrected' / 'predicted'."""
        col = self.corrected if kind == 'corrected' else self.predicted
        if col.values is None:
            return np.zeros(0, np.int64), np.zeros((0, 0))
        have = col.present.view().astype(bool)
        return self.stamp.view()[have], col.values.view()[have]
