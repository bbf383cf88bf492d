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
The acquisition search of the LED aligner: an expanding sweep of the base angle, per run.

Not in Solanki et al. (2018), who track from a known prior.  One axis: the base sweeps
center + a_j, center - a_{j+1}, ... with legs a_{j+1} = min(a_j + pitch, half_width) at
`speed` degrees per sample (the 1-D form of the constant-pitch spiral scan of optical
terminals), then keeps sweeping +-half_width.  A cold search (no last good angle) starts
with the leg cold_first, by default the whole half-width: a plain sweep.  Why:
doc/pointing.md.
"""

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import NDArray

from tskf_ros.led.intensity_model import AlignmentError, FloatArray

Mask = NDArray[np.bool_]


@dataclass(frozen=True)
class ScanConfig:
    """The sweep: degrees per sample, first leg, widening per leg, widest half-width."""

    speed: float = 3.0            # deg the base turns per sample while searching
    first: float = 15.0           # deg: half-width of the first leg around the center
    pitch: float = 25.0           # deg: each leg reaches this much further than the last
    half_width: float = 90.0      # deg: the search never leaves center +- this
    cold_first: float = 90.0      # deg: the first leg of a search with no last good angle

    def __post_init__(self) -> None:
        """Check the sweep; raise AlignmentError with the reason."""
        for name in ('speed', 'first', 'pitch', 'half_width', 'cold_first'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise AlignmentError(f'scan {name} must be a positive number of degrees, '
                                     f'got {value}')
        if max(self.first, self.cold_first) > self.half_width:
            raise AlignmentError(f'a first leg ({max(self.first, self.cold_first):g} deg) is '
                                 f'wider than the search half-width ({self.half_width:g} deg)')

    def worst_case_travel(self, cold: bool = False) -> float:
        """Return the degrees swept until both ends of center +- half_width were reached."""
        first = self.cold_first if cold else self.first
        travel, position, amplitude, direction = 0.0, 0.0, first, 1.0
        lo = hi = 0.0
        while not (lo <= -self.half_width and hi >= self.half_width):
            target = direction * amplitude
            travel += abs(target - position)
            lo, hi = min(lo, target), max(hi, target)
            position, direction = target, -direction
            amplitude = min(amplitude + self.pitch, self.half_width)
        return travel


class ExpandingSweep:
    """The expanding sweep of ScanConfig for every run; `turn` gives each run's next turn."""

    def __init__(self, config: ScanConfig, runs: int) -> None:
        self.config = config
        self.runs = int(runs)
        self.center = np.zeros(self.runs)
        self.amplitude = np.full(self.runs, config.cold_first)
        self.direction = np.ones(self.runs)
        self.legs = np.zeros(self.runs, dtype=int)

    def start(self, mask: Mask, center: FloatArray, *, cold: bool = False) -> None:
        """Begin a new search around center (deg, base angle) for the runs in mask."""
        self.center[mask] = np.asarray(center, dtype=float)[mask]
        self.amplitude[mask] = self.config.cold_first if cold else self.config.first
        self.direction[mask] = 1.0
        self.legs[mask] = 0

    def end_leg(self, mask: Mask) -> None:
        """End the current leg of the runs in mask where they are: turn around, widen."""
        self.direction[mask] = -self.direction[mask]
        self.amplitude[mask] = np.minimum(self.amplitude[mask] + self.config.pitch,
                                          self.config.half_width)
        self.legs[mask] += 1

    def turn(self, base: FloatArray, mask: Mask) -> FloatArray:
        """Return the next turn in degrees toward each leg's end for the runs in mask, else 0."""
        c = self.config
        target = self.center + self.direction * self.amplitude
        turn = np.clip(target - base, -c.speed, c.speed)
        # a run that reaches its leg's end turns around and widens the next leg
        self.end_leg(mask & (np.abs(target - base) <= c.speed))
        return np.where(mask, turn, 0.0)
