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

"""What a sample did: its status, the estimates and graininess to publish, the counters."""

from collections import Counter
from dataclasses import dataclass, field
from typing import NamedTuple, Optional, Union

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.units import NS

FloatArray = NDArray[np.float64]
# a measurement: a float when the model has one output, else p entries
Reading = Union[float, FloatArray]

# reasons a sample is not used; each is a diagnostics counter
REJECT_REASONS = ('zero_stamp', 'stamp_range', 'non_finite', 'bad_size', 'bad_variance',
                  'invalid_power',
                  'out_of_range', 'gated', 'future', 'duplicate', 'too_old', 'filter_error',
                  'input_non_finite', 'input_size', 'input_late', 'input_duplicate',
                  'input_zero_stamp', 'no_input_matrix')
RESET_REASONS = ('forward_jump', 'backward_jump', 'clock_jump', 'reconfigured',
                 'state_health', 'gate_lockout', 'set_state', 'service')


@dataclass(slots=True)
class Estimate:
    """One estimate: 'predicted' (xhat(t) from data before t) or 'corrected' (x(t|t))."""

    kind: str
    stamp_ns: int
    x: FloatArray
    P: FloatArray
    revised: bool = False


@dataclass(slots=True)
class Jump:
    """The graininess used at a point: mu(t) = sigma(t) - t."""

    stamp_ns: int
    sigma_ns: int
    revised: bool = False

    @property
    def mu(self) -> float:
        """Return mu in seconds."""
        return (self.sigma_ns - self.stamp_ns) / NS


@dataclass(slots=True)
class Outcome:
    """What one sample did: status, reason and message, and what to publish."""

    status: str                  # 'accepted', 'inserted', 'gap', 'rejected' or 'reset'
    reason: str = ''
    message: str = ''
    estimates: list[Estimate] = field(default_factory=list)
    jumps: list[Jump] = field(default_factory=list)


@dataclass(slots=True)
class Run:
    """
    Samples taken in one run (EstimatorSession.add_many): each accepted, appended in order.

    Sample k stepped the filter from the point at previous_ns[k] (its corrected estimate,
    x(t|t), P(t|t)) to its own stamp (the prediction): what add()'s Outcome holds as a
    corrected and a predicted estimate and one jump.
    """

    count: int
    stamps_ns: NDArray[np.int64]
    previous_ns: NDArray[np.int64]
    x_corrected: FloatArray         # count x n
    P_corrected: FloatArray         # count x n x n
    x_predicted: FloatArray
    P_predicted: FloatArray

    def outcomes(self) -> list[Outcome]:
        """Return the Outcome add() gives for each sample."""
        return [Outcome('accepted', '', '', [Estimate('corrected', t0, xc, Pc),
                                             Estimate('predicted', t1, xp, Pp)],
                        [Jump(t0, t1)])
                for t0, t1, xc, Pc, xp, Pp in zip(
                    self.previous_ns.tolist(), self.stamps_ns.tolist(), self.x_corrected,
                    self.P_corrected, self.x_predicted, self.P_predicted)]


class IntervalWarning(NamedTuple):
    """A sampling interval (in nominal periods) that breaks observability, and why."""

    kappa: int
    why: str


class PeakBounds(NamedTuple):
    """Theorem 2's bounds of the peak covariance for the intervals seen (scalar models)."""

    low: float
    high: float


@dataclass
class Stats:
    """Counters for diagnostics."""

    received: int = 0
    accepted: int = 0
    inserted: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    resets: Counter[str] = field(default_factory=Counter)
    mu_current: float = 0.0
    mu_max: float = 0.0
    gaps: dict[int, float] = field(default_factory=dict)    # stamp after the gap (ns) -> J (s)
    gaps_total: int = 0
    covariance_trace: float = 0.0
    last_stamp_ns: int = 0
    # since the last diagnostics report
    gaps_over_bound: int = 0
    rejected_since: int = 0
    # sampling intervals seen, in whole nominal periods (Fang & de Callafon's kappa)
    intervals: set[int] = field(default_factory=set)
    interval_warnings: list[IntervalWarning] = field(default_factory=list)
    peak_bounds: Optional[PeakBounds] = None
    # inputs (add_input)
    inputs_received: int = 0
    inputs_accepted: int = 0
    last_measurement_ns: int = 0
    # measurements the middleware reported lost before they reached the node (the live
    # node's message_lost event: a gap in the publisher's sequence, not a queue overflow)
    messages_lost: int = 0
