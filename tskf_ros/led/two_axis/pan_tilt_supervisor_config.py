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

"""The two-axis supervisor's settings: search, detection, lock tests, holds and actuation."""

from dataclasses import dataclass, field
import math
from typing import Optional

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.lock_detector import LockConfig
from tskf_ros.led.supervisor import STARTS
from tskf_ros.led.two_axis.spiral_search import SpiralConfig
from tskf_ros.led.two_axis.spot_detector import SpotConfig


@dataclass(frozen=True)
class PanTiltSupervisorConfig:
    """The supervisor's search, detection and lock tests, and its actuation budget."""

    spiral: SpiralConfig = field(default_factory=SpiralConfig)
    detector: SpotConfig = field(default_factory=SpotConfig)
    lock: LockConfig = field(default_factory=LockConfig)
    noise: float = 1.0            # V: sigma of v the fit assumes
    max_step: float = 45.0        # deg a command turns each axis at most; 0: no limit
    start: str = 'acquiring'      # or 'tracking': from the EKF's own x0, P0
    inflate: float = 4.0          # the hand-over variances are this times the Fisher bound,
    x1_var: tuple[float, float] = (0.01, 4.0)      # V^2: clipped to this range
    angle_var: tuple[float, float] = (2.0, 25.0)   # deg^2: and this one, per axis
    hold_samples: int = 100       # samples the EKF holds a declared loss before the search
    # V and samples: a loss of a light whose peak in good lock (x1hat g_r(0), averaged over
    # about a second, so that a sudden block leaves it high) was below fade_peak is held
    # for fade_hold samples instead: the two-axis form of the one-axis fade test.  The
    # link's x1 walk dims some lights under the noise (5 % below 1 V within 20 s), where
    # no intensity test tells a faded light from a pointing loss, and steering on the
    # drift model keeps the pointing where a search in the dark would carry it away
    fade_peak: float = 2.0
    fade_hold: int = 400
    # and only if x1_lock was at fade_peak or above since the hand-over: an EKF that
    # diverges from its start (the mean pointing up to offset0 + r off, x1 from the prior)
    # explains the dimming by x1, and never saw the light bright (False: any dim light)
    fade_seen: bool = True
    # deg: a fade hold that runs out looks (0: the search of a hold instead): one pass of
    # the spiral out to fade_look around the pointing the hold carried, its centre moving
    # as the drift model predicts the source; light seen: the hand-over; none: back to the
    # centre and the EKF as it was, and the hold again (fade_hold samples, then a look)
    fade_look: float = 0.0
    # samples of good lock since the hand-over (or the start) before a loss is held: a
    # lock lost sooner was on a fit off the light, and the hold would only delay the
    # search (on a cold start at 1 V, 2 of the 10 s)
    hold_after: int = 40
    # samples the spiral goes on after the CUSUM sees light, so that the fit sees the
    # light's crossing on both sides of its peak
    settle: int = 4
    # then a small spiral around the first fit (None: none), and the fit again from the
    # samples of both: one crossing of the light leaves c uncertain across the arm
    refine: Optional[SpiralConfig] = field(
        default_factory=lambda: SpiralConfig(speed=3.0, pitch=5.0, reach=9.0))
    min_samples: int = 10         # samples of a search before the CUSUM may see light
    # light the CUSUM saw before min_samples counts at min_samples (off by default): the
    # CUSUM falls again once the spiral has left a light crossed in its first samples; at
    # 1 V it gains 0 to 3 runs in 1000 of the cold start, but from 1.5 V it hands over
    # onto the dark's early false alarms (2.5 V: 73.9 % acquired within 10 s, not 79.2 %)
    early_light: bool = False
    # V: lost, too, when the EKF's peak x1hat g_r(0) falls below this (0: off).  At 1 V
    # of noise a pointing 15-20 deg off is explained as well by a dim light, but the link's
    # x1 walk dims 5 % of the lights below 1 V within 20 s, and the EKF that keeps steering
    # on its drift through the dim spell does better than a search; so off by default
    min_peak: float = 0.0
    # a hand-over that never came into good lock (onto no light, or a fit off it) resumes
    # the search where it stopped, on the spiral's next arm, instead of at its centre: the
    # spiral has already crossed the inner part, and a light near the fit is there too
    # (False: the centre again; at 1 V, 61 runs of 7000 not acquired within 10 s, 53 so)
    resume: bool = True
    # a hold that runs out while the EKF's peak x1hat g_r(0) is under the detector's
    # reference (k_ref: a light the spiral's CUSUM would not find) is held on as a fade,
    # fade_hold samples, instead of searching: a search in the dark only carries the
    # pointing away from where the drift model holds it (False: search; at 1 V, 149 runs
    # of 350 000 lost at the end against 109).  Only while the noise is under 2 k_ref, the
    # light the CUSUM is set for (`holds_dark`): at 2 V and 2.5 V, where a dark hold is
    # more often a lost pointing, it lost more runs (doc/design/two_axis.md)
    hold_dark: bool = True

    @property
    def fade_limit(self) -> int:
        """Return the samples a fade hold lasts from the declaration (never under a hold's)."""
        return max(self.fade_hold, self.hold_samples)

    @property
    def holds_dark(self) -> bool:
        """Tell whether a hold that runs out in the dark is held on (hold_dark, the noise)."""
        return self.hold_dark and self.noise < 2.0 * self.detector.reference

    def __post_init__(self) -> None:
        """Check the supervisor's settings; raise AlignmentError with the reason."""
        if self.start not in STARTS:
            raise AlignmentError(f'start must be one of {STARTS}, got {self.start!r}')
        for name in ('noise', 'max_step', 'inflate', 'min_peak', 'fade_peak', 'fade_look'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise AlignmentError(f'{name} must be >= 0, got {value}')
        if not self.noise > 0 or not self.inflate > 0:
            raise AlignmentError('noise and inflate must be > 0')
        if self.hold_samples < 0 or self.fade_hold < 0 or self.hold_after < 0:
            raise AlignmentError('hold_samples, fade_hold and hold_after must be >= 0')
        if self.settle < 0 or self.min_samples < 0:
            raise AlignmentError('settle and min_samples must be >= 0')
        for name in ('x1_var', 'angle_var'):
            lo, hi = getattr(self, name)
            if not (math.isfinite(hi) and 0.0 < lo <= hi):
                raise AlignmentError(f'{name} must be [lo, hi] with 0 < lo <= hi')
        if 0 < self.fade_look < self.spiral.pitch:
            raise AlignmentError(f'fade_look ({self.fade_look:g} deg) is less than the '
                                 f'spiral pitch ({self.spiral.pitch:g} deg)')
        if self.max_step > 0 and self.spiral.speed * 1.5 > self.max_step:
            raise AlignmentError('the spiral moves faster than max_step allows')
