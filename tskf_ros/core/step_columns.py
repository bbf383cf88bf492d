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
A filter trace's steps: one at a time (`StepRecord`) or as columns of a block (`StepColumns`).

The likelihood (`noise_fit.innovation_blocks`) reads a trace's steps a block at a time as
numpy columns, so that a run of measurement steps goes to the compiled filter as array
slices without a Python object per step.  A segment that keeps its steps as columns (the
session's `owc.trace_columns.TraceColumns`) gives them with `column_blocks()`; any other
sequence of `StepRecord`s is gathered into columns here.

No ROS.
"""

from dataclasses import dataclass
from typing import Iterator, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ['column_blocks', 'StepColumns', 'StepRecord']

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class StepRecord:
    """One step of the filter: mu (s), y (None: an input-only point) and the input u."""

    mu: float
    y: Optional[FloatArray]
    u: Optional[FloatArray] = None
    variance: float = 0.0       # the sample's own R_d (use_message_variance), 0: R / mu


@dataclass(frozen=True)
class StepColumns:
    """
    K steps as columns: mu (K), variance (K), has_y / has_u (K), y (K x p), u (K x m).

    y and u hold NaN rows where a step has none; None if no step of the block has one.
    records: the steps as given, if they came as StepRecords (record(i) gives them back).
    """

    mu: FloatArray
    variance: FloatArray
    has_y: BoolArray
    has_u: BoolArray
    y: Optional[FloatArray]
    u: Optional[FloatArray]
    records: Optional[Sequence[StepRecord]] = None

    def __len__(self) -> int:
        return int(self.mu.size)

    def record(self, i: int) -> StepRecord:
        """Return step i as a StepRecord (the one given, or made of the columns)."""
        if self.records is not None:
            return self.records[i]
        has_y, has_u = bool(self.has_y[i]), bool(self.has_u[i])
        return StepRecord(mu=float(self.mu[i]),
                          y=self.y[i].copy() if has_y and self.y is not None else None,
                          u=self.u[i].copy() if has_u and self.u is not None else None,
                          variance=float(self.variance[i]))

    @classmethod
    def of(cls, records: Sequence[StepRecord]) -> 'StepColumns':
        """Return the columns of records (each y, u flattened to a row)."""
        records = list(records)
        has_y = np.array([rec.y is not None for rec in records], dtype=bool)
        has_u = np.array([rec.u is not None for rec in records], dtype=bool)
        return cls(mu=np.array([rec.mu for rec in records], dtype=float),
                   variance=np.array([rec.variance for rec in records], dtype=float),
                   has_y=has_y, has_u=has_u, y=_rows([rec.y for rec in records], has_y),
                   u=_rows([rec.u for rec in records], has_u), records=records)


def _rows(values: list, present: BoolArray) -> Optional[FloatArray]:
    """Return the present values as rows (NaN rows elsewhere); None if none is present."""
    if not present.any():
        return None
    width = np.asarray(values[int(np.argmax(present))], dtype=float).size
    out = np.full((len(values), width), np.nan)
    for i in np.flatnonzero(present):
        out[i] = np.asarray(values[i], dtype=float).reshape(-1)
    return out


def column_blocks(segment: Sequence[StepRecord], block: int) -> Iterator[StepColumns]:
    """Yield a segment's steps as StepColumns of up to `block` steps (its own, if it has them)."""
    own = getattr(segment, 'column_blocks', None)
    if own is not None:
        yield from own()
        return
    chunk: list[StepRecord] = []
    for rec in segment:
        chunk.append(rec)
        if len(chunk) == block:
            yield StepColumns.of(chunk)
            chunk = []
    if chunk:
        yield StepColumns.of(chunk)
