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

"""The alignment session's record of the pointing supervisor: its state, transitions, losses."""

from dataclasses import dataclass, field
from typing import NamedTuple, Optional


class Transition(NamedTuple):
    """One change of the supervisor's state: from, to, why, at which sample stamp (ns)."""

    old: str                  # '' at the start
    new: str                  # acquiring, tracking, lost, or disabled (no supervisor)
    reason: str
    stamp_ns: Optional[int]   # the sample at which it happened (None: before any sample)


@dataclass
class PointingStats:
    """The supervisor's state since when, and its counters (for the 'pointing' task)."""

    state: str = ''
    since_ns: Optional[int] = None     # stamp of the sample the state began at
    transitions: int = 0
    acquisitions: int = 0              # hand-overs from a cold search
    losses: int = 0                    # losses declared by the lock tests
    reacquisitions: int = 0            # hand-overs after a loss
    requests: int = 0                  # searches forced by ~/acquire
    last_loss_ns: Optional[int] = None
    pending: list[Transition] = field(default_factory=list)

    def enter(self, state: str, reason: str, stamp_ns: Optional[int]) -> None:
        """Go to `state` (a transition if it differs, or on a forced search)."""
        if state == self.state and reason != 'acquire requested':
            return
        self.pending.append(Transition(self.state, state, reason, stamp_ns))
        if self.state:
            self.transitions += 1
        self.state, self.since_ns = state, stamp_ns

    def started(self, stamp_ns: int) -> None:
        """Date a state entered before any sample from the first sample's stamp."""
        if self.since_ns is None:
            self.since_ns = stamp_ns

    def take(self) -> list[Transition]:
        """Return the transitions not reported yet, oldest first, and forget them."""
        out, self.pending = self.pending, []
        return out

    def time_in_state(self, last_stamp_ns: int) -> float:
        """Return the seconds from the state's first sample to the last sample (0: none)."""
        if self.since_ns is None or not last_stamp_ns:
            return 0.0
        return max(last_stamp_ns - self.since_ns, 0) / 1e9
