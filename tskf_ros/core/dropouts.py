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
Measurement dropouts shared by both simulated links: Bernoulli and Gilbert-Elliott blockages.

A Gilbert-Elliott channel is a two-state Markov chain (good/bad) with P(good -> bad) =
p_gb and P(bad -> good) = p_bg per sample, and a loss probability in each state; its
stationary loss rate is (1 - pi_bad) loss_good + pi_bad loss_bad with pi_bad =
p_gb / (p_gb + p_bg).  Not from the papers (doc/design/core.md).
"""

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

BLOCKAGES = ('none', 'bernoulli', 'gilbert_elliott')
PROBABILITIES = ('drop_probability', 'ge_p_gb', 'ge_p_bg', 'ge_loss_good', 'ge_loss_bad')


@dataclass(frozen=True)
class Dropouts:
    """The blockage fields of a link config (a base class: its fields come first)."""

    blockage: str = 'none'            # 'none', 'bernoulli' or 'gilbert_elliott'
    drop_probability: float = 0.0     # Bernoulli p
    ge_p_gb: float = 0.01             # Gilbert-Elliott P(good -> bad) per sample
    ge_p_bg: float = 0.2              # P(bad -> good) per sample
    ge_loss_good: float = 0.0         # loss probability in the good state
    ge_loss_bad: float = 1.0          # loss probability in the bad state

    def check_dropouts(self, error: type[Exception]) -> None:
        """Raise `error` with the reason unless the blockage fields describe a channel."""
        if self.blockage not in BLOCKAGES:
            raise error(f'blockage must be one of {BLOCKAGES}, got {self.blockage!r}')
        for name in PROBABILITIES:
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise error(f'{name} is a probability, got {value}')
        if self.blockage == 'gilbert_elliott' and self.ge_p_gb + self.ge_p_bg <= 0:
            raise error('a Gilbert-Elliott channel needs ge_p_gb + ge_p_bg > 0')

    def expected_drop_rate(self) -> float:
        """Long-run fraction of samples lost to blockages (stationary Gilbert-Elliott)."""
        if self.blockage == 'bernoulli':
            return self.drop_probability
        if self.blockage == 'gilbert_elliott':
            bad = self.ge_p_gb / (self.ge_p_gb + self.ge_p_bg)
            return (1 - bad) * self.ge_loss_good + bad * self.ge_loss_bad
        return 0.0


def gilbert_elliott_states(u: NDArray[np.float64], p_gb: float, p_bg: float,
                           bad: bool) -> tuple[NDArray[np.bool_], bool]:
    """
    Return the channel states (True: bad) of the next u.size samples, and the state after.

    The channel is in state `bad` at the first sample; u[k] < p_gb (in the good state) or
    u[k] < p_bg (in the bad state) switches it after sample k.
    """
    n = u.size
    out = np.zeros(n, dtype=bool)
    leave_good = np.flatnonzero(u < p_gb)
    leave_bad = np.flatnonzero(u < p_bg)
    pos, state = 0, bool(bad)
    while pos < n:
        switches = leave_bad if state else leave_good
        i = int(np.searchsorted(switches, pos))
        end = int(switches[i]) + 1 if i < switches.size else n
        out[pos:end] = state
        if i < switches.size:
            state = not state
        pos = end
    return out, state
