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
Two-axis baselines with the conical-scan EKF's information: the samples and their stamps.

The two-axis forms of the baselines of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018,
Section V), in the tangent plane at the source (`pointing_geometry`), vectorised over runs:

- hill climbing (perturb and observe), axes alternating: each sample turns one axis by
  +-gamma, the axes taking turns; when a sample is not brighter than the one before, the
  axis whose turn led to it reverses its direction (its next turn goes back);
- four-point averaging, the two-axis form of three-point averaging (26): the receiver
  visits the four points gamma [+-1, 0], [0, +-1] around its mean pointing (a cross,
  the four beam positions of sequential lobing) and the mean pointing then turns per axis
  by (26), gamma_p = gamma (V+ - V-) / (V+ + V- + V3), with V3, the centre that the cross
  does not visit, read as the mean of the four samples.

A missing sample (NaN/None) makes both wait in place and measure again, as in one axis.
"""

import math

import numpy as np
from numpy.typing import NDArray

from tskf_ros.led.baselines import HILL_STEP
from tskf_ros.led.intensity_model import AlignmentError, FloatArray
from tskf_ros.led.scanning_ekf import as_measurement, Measurement, PAPER_DT, StampClock

# the four points of a cycle, in units of gamma: +c, -c, +e, -e
CROSS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


class _SteppingAligner:
    """What both baselines share: a turn step gamma, runs and a stamp clock."""

    def __init__(self, gamma: float, *, runs: int, dt: float) -> None:
        if not (math.isfinite(gamma) and gamma > 0.0):
            raise AlignmentError(f'gamma must be positive, got {gamma}')
        self.gamma = float(gamma)
        self.runs = int(runs)
        if self.runs < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self.clock = StampClock(dt)


class TwoAxisHillClimbing(_SteppingAligner):
    """Hill climbing in two axes: one axis turns by +-gamma per sample, the axes alternate."""

    def __init__(self, gamma: float = HILL_STEP, *, runs: int = 1, dt: float = PAPER_DT) -> None:
        super().__init__(gamma, runs=runs, dt=dt)
        self.direction = np.ones((self.runs, 2))
        self.reference = np.full(self.runs, np.nan)     # the last sample
        self.axis = np.zeros(self.runs, dtype=int)      # the axis of the next turn
        self.moved = np.full(self.runs, -1)             # the axis of the last turn (-1: none)

    @property
    def scan_offset(self) -> FloatArray:
        """Return [0, 0]: the turns are commands, not a scan."""
        return np.zeros(2)

    def restart_runs(self, mask: NDArray[np.bool_]) -> None:
        """Start the runs in mask afresh: no reference, +gamma on the first axis first."""
        self.direction[mask] = 1.0
        self.reference[mask] = np.nan
        self.axis[mask] = 0
        self.moved[mask] = -1

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Compare z with the last sample, reverse the last turned axis if it did not rise."""
        z = as_measurement(z, self.runs)
        self.clock.tick(stamp)
        have = np.isfinite(z)
        rows = np.arange(self.runs)
        worse = have & np.isfinite(self.reference) & ~(z > self.reference) & (self.moved >= 0)
        self.direction[rows[worse], self.moved[worse]] *= -1.0
        self.reference = np.where(have, z, self.reference)
        turn = np.zeros((self.runs, 2))
        turn[rows[have], self.axis[have]] = self.gamma * self.direction[rows[have],
                                                                        self.axis[have]]
        self.moved = np.where(have, self.axis, self.moved)
        self.axis = np.where(have, 1 - self.axis, self.axis)
        return turn


class FourPointAveraging(_SteppingAligner):
    """
    Four-point averaging: the cross of CROSS around the mean pointing, then (26) per axis.

    The receiver is at mean + gamma CROSS[phase] when a sample is taken (`scan_offset`,
    per run); after the fourth the mean pointing turns by
    gamma_p = gamma (V+ - V-) / (V+ + V- + V3), V3 = the mean of the four, on each axis.
    clip=True (as the one-axis clip, not in the paper) makes gamma_p 0 when its
    denominator is not positive and clips it to [-gamma, gamma].  `step` returns the
    receiver's turn: that of the mean pointing plus the move to the next point.
    """

    def __init__(self, gamma: float = HILL_STEP, *, runs: int = 1, dt: float = PAPER_DT,
                 clip: bool = False) -> None:
        super().__init__(gamma, runs=runs, dt=dt)
        self.clip = bool(clip)
        self.phase = np.zeros(self.runs, dtype=int)     # the point the receiver is at
        self.v = np.zeros((self.runs, 4))               # V at +c, -c, +e, -e this cycle

    @property
    def scan_offset(self) -> FloatArray:
        """Return the offsets (runs, 2) of the receiver from its mean pointing."""
        return self.gamma * CROSS[self.phase]

    def restart_runs(self, mask: NDArray[np.bool_]) -> None:
        """Start the runs in mask afresh: a new cycle (the receiver stays where it is)."""
        self.v[mask] = 0.0

    def averaged_turn(self) -> FloatArray:
        """Return gamma_p (runs, 2) of (26) per axis from this cycle's four samples."""
        g = self.gamma
        v = self.v
        v3 = np.mean(v, axis=1)
        plus, minus = v[:, [0, 2]], v[:, [1, 3]]
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
            total = plus + minus + v3[:, None]
            # (26): gamma_p = (gamma V1 - gamma V2) / (V1 + V2 + V3), V3 the mean of the four
            gamma_p = g * (plus - minus) / total
        if self.clip:
            gamma_p = np.clip(np.where(total > 0.0, gamma_p, 0.0), -g, g)
        return np.where(np.isfinite(gamma_p), gamma_p, 0.0)      # 0/0: no turn

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Record V at this point; return the turn to the next point (and the new mean)."""
        z = as_measurement(z, self.runs)
        self.clock.tick(stamp)
        have = np.isfinite(z)
        rows = np.arange(self.runs)
        self.v[rows[have], self.phase[have]] = z[have]
        ends = have & (self.phase == len(CROSS) - 1)
        mean_turn = np.where(ends[:, None], self.averaged_turn(), 0.0)
        here = self.scan_offset
        self.phase = np.where(have, (self.phase + 1) % len(CROSS), self.phase)
        return mean_turn + self.scan_offset - here
