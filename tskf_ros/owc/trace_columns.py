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
by (segment, stamp), and makes the older ones final: rows, oldest first (segment, then
stamp), as the dicts sorted at the end would give:

- TraceColumns: the filter steps (mu, y, u, the sample's variance), segment by segment,
  read back as `StepRecord`s one at a time (a Sequence of segments, each a Sequence of
  records, as `noise_fit` takes), kept in a temporary file (`core.spill_rows`):
  8 (2 + p + m) + 2 bytes a step on disk, a block in memory;
- InnovationColumns: the innovation e_k and S_k of each measurement step, its NIS and
  log det S_k, in a temporary file too (8 (2 + p + p^2) bytes); their sums are np.sum's
  of the whole columns (`core.pairwise_sum`);
- EstimateColumns: the final corrected x(t|t) and predicted xhat(t) at each stamp (only
  if asked for: the sweep's truth errors), in memory: 8 (2 + 2 n) + 2 bytes a stamp.

No ROS.
"""

from typing import Iterator, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.growing_column import Column
from tskf_ros.core.nis_check import nis_summary_of, NisSummary, single_band
from tskf_ros.core.noise_fit import innovation_terms, Innovations, log_likelihood_of
from tskf_ros.core.pairwise_sum import PairwiseSum
from tskf_ros.core.spill_rows import SpillRows
from tskf_ros.core.step_columns import StepColumns, StepRecord

__all__ = ['EstimateColumns', 'InnovationColumns', 'TraceColumns']

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


class _SpilledOptional:
    """A spilled column of arrays, some rows absent, the width set by the first present."""

    def __init__(self) -> None:
        self.values: Optional[SpillRows] = None
        self.missing = 0            # rows absent before the first present one

    def append(self, value: Optional[FloatArray]) -> None:
        if value is None:
            if self.values is None:
                self.missing += 1
            else:
                self.values.append(np.nan)
            return
        if self.values is None:
            self.values = SpillRows(np.dtype((np.float64, np.shape(value))))
            self.values.extend(np.full((self.missing, *np.shape(value)), np.nan))
        self.values.append(value)

    def read(self, start: int, count: int) -> Optional[NDArray]:
        """Return rows start .. start + count - 1 (None: no row was ever present)."""
        return None if self.values is None else self.values.read(start, count)

    def close(self) -> None:
        if self.values is not None:
            self.values.close()


_STEP = np.dtype([('mu', np.float64), ('variance', np.float64), ('has_y', np.int8),
                  ('has_u', np.int8)])


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
        return self.trace.records(self.start, self.end)

    def column_blocks(self) -> Iterator[StepColumns]:
        """Yield the segment's steps as columns, a block at a time (step_columns)."""
        return self.trace.column_blocks(self.start, self.end)


class TraceColumns(Sequence[Sequence[StepRecord]]):
    """The filter steps of a run, segment by segment, in a temporary file (close() frees it)."""

    def __init__(self) -> None:
        self._steps = SpillRows(_STEP)
        self.y = _SpilledOptional()
        self.u = _SpilledOptional()
        self.starts: list[int] = []     # first row of each segment
        self.segment: Optional[int] = None
        self.measurement_steps = 0      # steps with a y

    def append(self, segment: int, rec: StepRecord) -> None:
        """Add a step of `segment` (segments in order, each step after the previous)."""
        if segment != self.segment:
            self.starts.append(len(self._steps))
            self.segment = segment
        self._steps.append((rec.mu, rec.variance, rec.y is not None, rec.u is not None))
        self.measurement_steps += rec.y is not None
        self.y.append(None if rec.y is None else np.asarray(rec.y, dtype=float))
        self.u.append(None if rec.u is None else np.asarray(rec.u, dtype=float))

    def column_blocks(self, start: int, end: int) -> Iterator[StepColumns]:
        """Yield steps start .. end - 1 (over all segments) as columns, a block at a time."""
        block = self._steps.block
        for first in range(start, end, block):
            count = min(block, end - first)
            steps = self._steps.read(first, count)
            yield StepColumns(mu=steps['mu'], variance=steps['variance'],
                              has_y=steps['has_y'].astype(bool),
                              has_u=steps['has_u'].astype(bool),
                              y=self.y.read(first, count), u=self.u.read(first, count))

    def records(self, start: int, end: int) -> Iterator[StepRecord]:
        """Yield steps start .. end - 1 (counted over all segments), a block read at a time."""
        for cols in self.column_blocks(start, end):
            for i in range(len(cols)):
                yield cols.record(i)

    def record(self, k: int) -> StepRecord:
        """Return step k (counted over all segments)."""
        return next(self.records(k, k + 1))

    @property
    def steps(self) -> int:
        """Return the number of steps over all segments."""
        return len(self._steps)

    def __len__(self) -> int:
        return len(self.starts)

    def __getitem__(self, i):  # int or slice, as a Sequence
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        i = range(len(self))[i]
        ends = self.starts[1:] + [self.steps]
        return _SegmentView(self, self.starts[i], ends[i])

    def close(self) -> None:
        """Free the temporary files (the steps are gone)."""
        self._steps.close()
        self.y.close()
        self.u.close()


class InnovationColumns:
    """
    The innovations of a run's measurement steps, in a temporary file (close() frees it).

    `extend(e, S)` adds a block (NIS and log det S from innovation_terms); count,
    log_likelihood() and nis_summary() read them back a block at a time.  The arrays
    (`e`, `S`, `nis`, `log_det_S`, `arrays()`) read them all into memory: for short runs.
    """

    def __init__(self, p: int) -> None:
        self.p = p
        self._rows = SpillRows(np.dtype([('e', np.float64, (p,)), ('S', np.float64, (p, p)),
                                         ('nis', np.float64), ('log_det_S', np.float64)]))

    def extend(self, e: FloatArray, S: FloatArray) -> None:
        """Add innovations e (N x p) and their covariances S (N x p x p)."""
        if not len(S):
            return
        nis, log_det = innovation_terms(e, S)
        rows = np.empty(len(S), self._rows.dtype)
        rows['e'] = np.asarray(e, dtype=float).reshape(len(S), self.p)
        rows['S'], rows['nis'], rows['log_det_S'] = S, nis, log_det
        self._rows.extend(rows)

    @property
    def count(self) -> int:
        """Return the number of measurement steps N."""
        return len(self._rows)

    def _sum(self, name: str) -> np.float64:
        total = PairwiseSum(self.count)
        for block in self._rows.blocks():
            total.add(block[name])
        return total.total()

    def log_likelihood(self) -> float:
        """Return log L = -1/2 sum [log det S + e^T S^-1 e + p log 2 pi] (Innovations')."""
        return log_likelihood_of(self._sum('log_det_S'), self._sum('nis'), self.count, self.p)

    def nis_summary(self, level: float = 0.95) -> NisSummary:
        """Return nis_summary of the NIS, read a block at a time."""
        lo, hi = single_band(self.p, level)
        inside = sum(int(np.count_nonzero((b['nis'] >= lo) & (b['nis'] <= hi)))
                     for b in self._rows.blocks())
        return nis_summary_of(self.count, self._sum('nis'), inside, self.p, level)

    def arrays(self) -> Innovations:
        """Return every innovation in memory."""
        rows = self._rows.read(0, self.count)
        return Innovations(rows['e'], rows['S'], rows['nis'], rows['log_det_S'])

    @property
    def e(self) -> FloatArray:
        """Return the innovations e_k (N x p), read into memory."""
        return self.arrays().e

    @property
    def S(self) -> FloatArray:
        """Return the covariances S_k (N x p x p), read into memory."""
        return self.arrays().S

    @property
    def nis(self) -> FloatArray:
        """Return NIS_k (N), read into memory."""
        return self.arrays().nis

    @property
    def log_det_S(self) -> FloatArray:
        """Return log det S_k (N), read into memory."""
        return self.arrays().log_det_S

    def close(self) -> None:
        """Free the temporary file."""
        self._rows.close()


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
