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
The events of a recorded stream (measurements and inputs), kept as compact columns.

A bag read for an analysis is fed to the estimator session more than once (fit_noise
runs it once per round of its gate), so its events are kept; as objects they cost about
0.3 KB a message, as columns 8 (4 + p) + 1 bytes a measurement (stamp, receiver time,
variance, value, which kind) and 8 (1 + m) an input.  `EventColumns` is appended to as
the bag is read and iterated as often as needed; each iteration makes the Measurement and
Input objects one at a time, in the order they were added, with the values they were
added with (float64).

No ROS, no I/O.
"""

from dataclasses import dataclass
from typing import AbstractSet, Iterator, Optional, Union

import numpy as np
from numpy.typing import ArrayLike

from tskf_ros.core.growing_column import Column

__all__ = ['Column', 'Event', 'EventColumns', 'Input', 'Measurement']

# events made into objects at a time
_BLOCK = 4096
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
    Measurements and inputs in arrival order, as columns; iterate for the events.

    p: values per measurement; m: values per input.  A measurement's value is kept with p
    entries (a scalar when p = 1, as read), an input's u with m.
    """

    def __init__(self, p: int = 1, m: int = 1) -> None:
        self.p, self.m = p, m
        self.kind = Column(np.int8)
        self.stamp = Column(np.int64)
        self.log_ns = Column(np.int64)        # measurements only, in their order
        self.variance = Column(np.float64)
        self.value = Column(np.float64, (p,))
        self.u = Column(np.float64, (m,))    # inputs only, in their order

    def append(self, event: Event) -> None:
        """Add an event (a Measurement or an Input) at the end."""
        if isinstance(event, Input):
            u = np.asarray(event.u, dtype=float).reshape(-1)
            if u.size != self.m:
                raise ValueError(f'an input of {u.size} values, expected {self.m}')
            self.kind.append(_INPUT)
            self.stamp.append(int(event.stamp_ns))
            self.u.append(u)
            return
        value = np.asarray(event.value, dtype=float).reshape(-1)
        if value.size != self.p:
            raise ValueError(f'a measurement of {value.size} values, expected {self.p}')
        self.kind.append(_MEASUREMENT)
        self.stamp.append(int(event.stamp_ns))
        self.log_ns.append(_NO_LOG if event.log_ns is None else int(event.log_ns))
        self.variance.append(float(event.variance))
        self.value.append(value)

    @property
    def measurements(self) -> int:
        """Return the number of measurements."""
        return self.log_ns.count

    @property
    def inputs(self) -> int:
        """Return the number of inputs."""
        return self.u.count

    def __len__(self) -> int:
        return self.kind.count

    def __iter__(self) -> Iterator[Event]:
        return self.events()

    def events(self, without: AbstractSet[int] = frozenset()) -> Iterator[Event]:
        """Yield the events in order, leaving out the measurements stamped in `without`."""
        kinds, stamps = self.kind.view(), self.stamp.view()
        logs, variances, values, us = (self.log_ns.view(), self.variance.view(),
                                       self.value.view(), self.u.view())
        scalar = self.p == 1
        i_m = i_u = 0
        for start in range(0, len(kinds), _BLOCK):
            # a block at a time as Python numbers: int64 and float64 scalars would leak
            # into the session's arithmetic
            block = slice(start, start + _BLOCK)
            for kind, stamp in zip(kinds[block].tolist(), stamps[block].tolist()):
                if kind == _INPUT:
                    yield Input(stamp, us[i_u].copy())
                    i_u += 1
                    continue
                k, i_m = i_m, i_m + 1
                if stamp in without:
                    continue
                log = int(logs[k])
                yield Measurement(stamp, float(values[k, 0]) if scalar else values[k].copy(),
                                  float(variances[k]), None if log == _NO_LOG else log)
