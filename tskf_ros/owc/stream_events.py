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
The events of a recorded stream (measurements and inputs), kept as compact rows.

A bag read for an analysis is fed to the estimator session more than once (fit_noise
runs it once per round of its gate), so its events are kept; as objects they cost about
0.3 KB a message, as rows 8 (3 + p + m) + 1 bytes an event (which kind, stamp, receiver
time, variance, value, input), in a temporary file (`core.spill_rows`: a block in
memory, whatever the bag's length).  `EventColumns` is appended to as the bag is read
and iterated as often as needed; each iteration makes the Measurement and Input objects
one at a time, in the order they were added, with the values they were added with
(float64).

No ROS.
"""

from dataclasses import dataclass
from typing import AbstractSet, Iterator, Optional, Union

import numpy as np
from numpy.typing import ArrayLike

from tskf_ros.core.spill_rows import SpillRows

__all__ = ['Event', 'EventColumns', 'Input', 'Measurement']

# kinds of row
_MEASUREMENT, _INPUT = 0, 1
# a measurement without a receiver time (log_ns None)
_NO_LOG = np.iinfo(np.int64).min


@dataclass(frozen=True)
class Measurement:
    """A measurement sample: stamp (ns), value(s), variance, and the receiver time (ns)."""

    stamp_ns: int
    value: ArrayLike
    variance: float = 0.0
    log_ns: Optional[int] = None


@dataclass(frozen=True)
class Input:
    """An input sample u at a stamp (ns)."""

    stamp_ns: int
    u: ArrayLike


Event = Union[Measurement, Input]


class EventColumns:
    """
    Measurements and inputs in arrival order, as rows; iterate for the events.

    p: values per measurement; m: values per input.  A measurement's value is kept with p
    entries (a scalar when p = 1, as read), an input's u with m.  The rows are in a
    temporary file: close() frees it (so does the end of the process, however it ends).
    """

    def __init__(self, p: int = 1, m: int = 1) -> None:
        self.p, self.m = p, m
        self.rows = SpillRows(np.dtype([
            ('kind', np.int8), ('stamp', np.int64), ('log_ns', np.int64),
            ('variance', np.float64), ('value', np.float64, (p,)), ('u', np.float64, (m,))]))
        self._measurements = self._inputs = 0

    def append(self, event: Event) -> None:
        """Add an event (a Measurement or an Input) at the end."""
        if isinstance(event, Input):
            u = np.asarray(event.u, dtype=float).reshape(-1)
            if u.size != self.m:
                raise ValueError(f'an input of {u.size} values, expected {self.m}')
            self.rows.append((_INPUT, int(event.stamp_ns), _NO_LOG, 0.0, 0.0, u))
            self._inputs += 1
            return
        value = np.asarray(event.value, dtype=float).reshape(-1)
        if value.size != self.p:
            raise ValueError(f'a measurement of {value.size} values, expected {self.p}')
        self.rows.append((_MEASUREMENT, int(event.stamp_ns),
                          _NO_LOG if event.log_ns is None else int(event.log_ns),
                          float(event.variance), value, 0.0))
        self._measurements += 1

    @property
    def measurements(self) -> int:
        """Return the number of measurements."""
        return self._measurements

    @property
    def inputs(self) -> int:
        """Return the number of inputs."""
        return self._inputs

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self) -> Iterator[Event]:
        return self.events()

    def events(self, without: AbstractSet[int] = frozenset()) -> Iterator[Event]:
        """Yield the events in order, leaving out the measurements stamped in `without`."""
        scalar = self.p == 1
        for block in self.rows.blocks():
            # a block at a time as Python numbers: int64 and float64 scalars would leak
            # into the session's arithmetic
            values, us = block['value'], block['u']
            rows = zip(block['kind'].tolist(), block['stamp'].tolist(),
                       block['log_ns'].tolist(), block['variance'].tolist())
            for i, (kind, stamp, log, variance) in enumerate(rows):
                if kind == _INPUT:
                    yield Input(stamp, us[i].copy())
                    continue
                if stamp in without:
                    continue
                yield Measurement(stamp, float(values[i, 0]) if scalar else values[i].copy(),
                                  variance, None if log == _NO_LOG else log)

    def close(self) -> None:
        """Free the temporary file (the events are gone)."""
        self.rows.close()
