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
The acquisition search of the pan-tilt receiver: an Archimedean spiral, per run.

The two-axis form of acquisition_scan's expanding sweep (the constant-pitch spiral scan
of optical terminals): around a centre direction c (joints [pan, tilt]) the boresight
follows the directions displaced from c by (pointing_geometry.displaced, exact on the
sphere; tangent-plane turns do not add up to positions on a sphere)

    p(phi) = a phi [cos phi, sin phi],   a = pitch / (2 pi)

out to the radius `reach`, and starts again at c (a new spiral, turned by half a turn,
so that its arms fall between the last ones).  It advances `speed` degrees of path per
sample: d phi = speed / (a sqrt(1 + phi^2)), the arc length element of the spiral.  A
pitch below the width over which the light is seen leaves no gap: with the default 12
deg pitch every direction within `reach` is at most 6 deg from an arm, where the radial
response is 70 % of its peak.  The time to cover a disc of radius R is about
pi R^2 / (pitch speed) samples (the spiral's length): 96 samples (4.8 s) to 38 deg.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from tskf_ros.led.acquisition_scan import Mask
from tskf_ros.led.intensity_model import AlignmentError, FloatArray
from tskf_ros.led.two_axis.pointing_geometry import displaced, joint_turn, turn_between


@dataclass(frozen=True)
class SpiralConfig:
    """The spiral: degrees of path per sample, degrees between arms, the widest radius."""

    speed: float = 4.0            # deg the boresight moves per sample while searching
    pitch: float = 12.0           # deg between successive arms
    reach: float = 38.0           # deg: the spiral starts again beyond this radius (a 30
    # deg cone, the light seen some 8 deg off an arm, and the drift while searching)

    def __post_init__(self) -> None:
        """Check the spiral; raise AlignmentError with the reason."""
        for name in ('speed', 'pitch', 'reach'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise AlignmentError(f'spiral {name} must be a positive number of degrees, '
                                     f'got {value}')
        if self.reach < self.pitch:
            raise AlignmentError(f'the spiral reach ({self.reach:g} deg) is less than its '
                                 f'pitch ({self.pitch:g} deg)')

    def samples_to_cover(self, radius: float) -> int:
        """Return the samples the spiral takes to reach `radius` from its centre."""
        a = self.pitch / (2.0 * math.pi)
        phi = radius / a
        # arc length of r = a phi from 0 to phi
        length = a / 2.0 * (phi * math.sqrt(1.0 + phi * phi) + math.asinh(phi))
        return int(math.ceil(length / self.speed))


class SpiralSearch:
    """The spiral of SpiralConfig for every run; `turn` gives each run's next turn."""

    def __init__(self, config: SpiralConfig, runs: int) -> None:
        self.config = config
        self.runs = int(runs)
        self.center = np.zeros((self.runs, 2))      # joints [pan, tilt] of the centre
        self.phi = np.zeros(self.runs)               # the spiral's angle parameter (rad)
        self.phase = np.zeros(self.runs)             # its orientation (rad)
        self.spirals = np.zeros(self.runs, dtype=int)
        self.rate = np.zeros((self.runs, 2))        # tangent-plane turn of c per sample
        self.reach = np.full(self.runs, config.reach)

    def start(self, mask: Mask, center: FloatArray, rate: Optional[FloatArray] = None,
              reach: Optional[float] = None) -> None:
        """
        Begin a new spiral around the joints `center` (runs, 2) for the runs in mask.

        rate: the tangent-plane turn (runs, 2) of the centre per sample (None: still), for a
        search that follows a drift model; reach: its widest radius (None: the config's).
        """
        self.center[mask] = np.asarray(center, dtype=float)[mask]
        self.rate[mask] = 0.0 if rate is None else np.asarray(rate, dtype=float)[mask]
        self.reach[mask] = self.config.reach if reach is None else float(reach)
        self.phi[mask] = 0.0
        self.phase[mask] = 0.0
        self.spirals[mask] = 0

    def point(self) -> FloatArray:
        """Return the joints (runs, 2) of the spiral's current point p(phi) around c."""
        a = self.config.pitch / (2.0 * math.pi)
        angle = self.phi + self.phase
        p = (a * self.phi)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
        return displaced(self.center[:, 0], self.center[:, 1], p)

    def turn(self, joints: FloatArray, mask: Mask) -> FloatArray:
        """Advance the runs in mask; return their turns (runs, 2) to their next points."""
        if not np.any(mask):    # no run searching (a tracking node's every sample): no change
            return np.zeros_like(self.center)
        c = self.config
        a = c.pitch / (2.0 * math.pi)
        # d phi = speed / |dp/dphi|, |dp/dphi| = a sqrt(1 + phi^2)
        step = c.speed / (a * np.sqrt(1.0 + self.phi * self.phi))
        before = self.phi.copy()
        self.phi = np.where(mask, self.phi + step, self.phi)
        # the centre follows its rate (zero unless the search follows a drift model)
        moved = joint_turn(np.where(mask[:, None], self.rate, 0.0), self.center[:, 1])
        self.center = self.center + moved
        beyond = mask & (a * self.phi > self.reach)
        # a new spiral, half a turn round from the last
        self.phi[beyond] = 0.0
        self.phase[beyond] += math.pi
        self.spirals[beyond] += 1
        turn = turn_between(joints, self.point())
        # never more than `speed` per sample (the jump back to the centre takes samples)
        size = np.hypot(turn[:, 0], turn[:, 1])
        scale = np.minimum(1.0, c.speed * 1.5 / np.maximum(size, 1e-12))
        jump = beyond | (size > c.speed * 1.5)
        turn = np.where(jump[:, None], turn * scale[:, None], turn)
        # a run still travelling holds its spiral where it was: at the centre after a new
        # spiral, or where a resumed one stopped
        travelling = jump & (scale < 1.0)
        self.phi[travelling] = np.where(beyond, 0.0, before)[travelling]
        return np.where(mask[:, None], turn, 0.0)
