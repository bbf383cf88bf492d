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
The baselines of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018), Section V.

Hill-climbing with step gamma = 2 degrees, and three-point averaging (26)
gamma_p = gamma (V1 - V2) / (V1 + V2 + V3); `make_aligner` builds any of ALGORITHMS.
"""

import math
from typing import Optional, Union

import numpy as np
from numpy.typing import NDArray

from tskf_ros.led.intensity_model import AlignmentError, FloatArray, IncidenceResponse
from tskf_ros.led.lqg_alignment import LQGAligner, LQGConfig
from tskf_ros.led.scanning_ekf import (as_measurement, EKFConfig, Measurement, PAPER_DT,
                                       ScanningEKF, StampClock)

HILL_STEP = 2.0                 # degrees, gamma of Section V


class _SteppingAligner:
    """What both baselines share: a turn step gamma, runs, a stamp clock and no scan."""

    def __init__(self, gamma: float, *, runs: int, dt: float) -> None:
        if not (math.isfinite(gamma) and gamma > 0.0):
            raise AlignmentError(f'gamma must be positive, got {gamma}')
        self.gamma = float(gamma)
        self.runs = int(runs)
        self.clock = StampClock(dt)

    @property
    def scan_offset(self) -> float:
        """Return 0: the baselines' turns are commands, not a scan."""
        return 0.0

    def correct_last_turn(self, delta: FloatArray) -> None:
        """Ignore a clamped turn: the baselines compare intensities, they keep no angle."""


class HillClimbing(_SteppingAligner):
    """
    Hill-climbing (Section V): keep turning by gamma while the intensity rises.

    A missing measurement makes it wait one step in place (command 0) and measure again.
    """

    def __init__(self, gamma: float = HILL_STEP, *, runs: int = 1, dt: float = PAPER_DT) -> None:
        super().__init__(gamma, runs=runs, dt=dt)
        self.direction = np.ones(self.runs)
        self.reference = np.full(self.runs, np.nan)

    def restart_runs(self, mask: NDArray[np.bool_]) -> None:
        """Start the runs in mask afresh: no reference, turning +gamma first."""
        self.direction[mask] = 1.0
        self.reference[mask] = np.nan

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Compare z with the last measurement, reverse if it did not rise, return the turn."""
        z = as_measurement(z, self.runs)
        self.clock.tick(stamp)
        have = np.isfinite(z)
        worse = have & np.isfinite(self.reference) & ~(z > self.reference)
        self.direction = np.where(worse, -self.direction, self.direction)
        self.reference = np.where(have, z, self.reference)
        return np.where(have, self.direction * self.gamma, 0.0)


class ThreePointAveraging(_SteppingAligner):
    """
    Three-point averaging (Section V, eq. (26)), vectorised over runs.

    A cycle measures V3 at the current orientation, V1 after turning by +gamma and V2
    at -gamma, then turns to the new orientation by gamma_p = gamma (V1 - V2) /
    (V1 + V2 + V3) (26), as printed: with noise the denominator can come close to zero
    and gamma_p be huge.  clip=True (not in the paper) makes gamma_p 0 when the
    denominator is not positive and clips it to [-gamma, gamma], its noise-free range.
    A missing measurement repeats that phase of the cycle in place.
    """

    def __init__(self, gamma: float = HILL_STEP, *, runs: int = 1, dt: float = PAPER_DT,
                 clip: bool = False) -> None:
        super().__init__(gamma, runs=runs, dt=dt)
        self.clip = bool(clip)
        self.phase = np.zeros(self.runs, dtype=int)   # 0: at origin, 1: at +gamma, 2: at -gamma
        self.v = np.zeros((self.runs, 3))             # V1, V2, V3 of the current cycle
        self.offset = np.zeros(self.runs)

    def restart_runs(self, mask: NDArray[np.bool_]) -> None:
        """Start the runs in mask afresh: a new cycle at the current orientation."""
        self.phase[mask] = 0
        self.v[mask] = 0.0

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Record V for this phase, return the turn to the next phase's orientation."""
        z = as_measurement(z, self.runs)
        self.clock.tick(stamp)
        have = np.isfinite(z)
        g = self.gamma
        cmd = np.zeros(self.runs)
        at0, at1, at2 = (have & (self.phase == phase) for phase in range(3))
        self.v[at0, 2] = z[at0]
        self.v[at1, 0] = z[at1]
        self.v[at2, 1] = z[at2]
        cmd[at0] = g                     # origin -> +gamma
        cmd[at1] = -2.0 * g              # +gamma -> -gamma
        v1, v2, v3 = self.v[:, 0], self.v[:, 1], self.v[:, 2]
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
            total = v1 + v2 + v3
            # (26): gamma_p = (gamma V1 - gamma V2) / (V1 + V2 + V3)
            gamma_p = g * (v1 - v2) / total
        if self.clip:
            gamma_p = np.clip(np.where(total > 0.0, gamma_p, 0.0), -g, g)
        gamma_p = np.where(np.isfinite(gamma_p), gamma_p, 0.0)   # 0/0: no turn
        cmd[at2] = g + gamma_p[at2]      # -gamma -> origin + gamma_p
        self.phase = np.where(have, (self.phase + 1) % 3, self.phase)
        return cmd


ALGORITHMS = ('ekf', 'hill_climbing', 'three_point')
# the EKF's controller: the paper's P controller (21), or the LQG of lqg_alignment
CONTROLLERS = ('p', 'lqg')
# the aligner of each of ALGORITHMS (the EKF with either controller)
AnyAligner = Union[ScanningEKF, LQGAligner, HillClimbing, ThreePointAveraging]


def make_aligner(name: str, *, runs: int = 1, dt: float = PAPER_DT,
                 response: Optional[IncidenceResponse] = None,
                 ekf: Optional[EKFConfig] = None, gamma: float = HILL_STEP,
                 clip: bool = False, controller: str = 'p',
                 lqg: Optional[LQGConfig] = None) -> AnyAligner:
    """Build the aligner called `name` (one of ALGORITHMS); clip is for three_point."""
    if controller not in CONTROLLERS:
        raise AlignmentError(f'unknown controller {controller!r}; expected one of {CONTROLLERS}')
    if name == 'ekf' and controller == 'lqg':
        return LQGAligner(lqg if lqg is not None else LQGConfig(dt=dt), response, runs=runs)
    if name == 'ekf':
        config = ekf if ekf is not None else EKFConfig(dt=dt)
        return ScanningEKF(config, response, runs=runs)
    if name == 'hill_climbing':
        return HillClimbing(gamma, runs=runs, dt=dt)
    if name == 'three_point':
        return ThreePointAveraging(gamma, runs=runs, dt=dt, clip=clip)
    raise AlignmentError(f'unknown algorithm {name!r}; expected one of {ALGORITHMS}')
