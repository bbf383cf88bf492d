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
The alignment node's pointing settings (pat.*): the supervisor's search, detection and lock.

Not in Solanki et al. (2018), who track from a known prior: the acquiring / tracking /
lost supervisor of tskf_ros.led.supervisor; the defaults are its own (SupervisorConfig),
those of the Monte Carlo experiment (doc/pointing.md says why).
"""

from dataclasses import dataclass

from tskf_ros.led.acquisition_scan import ScanConfig
from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.light_detector import DetectorConfig
from tskf_ros.led.lock_detector import LockConfig
from tskf_ros.led.supervisor import STARTS, SupervisorConfig

_SCAN, _DETECTOR, _LOCK, _SUP = ScanConfig(), DetectorConfig(), LockConfig(), SupervisorConfig()


@dataclass(frozen=True)
class PatConfig:
    """Whether the supervisor runs, how it starts, and its sweep, CUSUM and lock tests."""

    enabled: bool = True                  # False: the bare aligner (Table I reproduction)
    start: str = 'acquiring'              # or 'tracking': from the aligner's x0, P0
    reacquire: bool = True                # False: a loss restarts the aligner in place
    scan_speed: float = _SCAN.speed       # deg per sample while searching
    scan_first: float = _SCAN.first       # deg: first leg of a re-acquisition
    scan_pitch: float = _SCAN.pitch       # deg each leg widens
    scan_half_width: float = _SCAN.half_width     # deg: the search stays within +- this
    scan_cold_first: float = _SCAN.cold_first     # deg: first leg of a cold search
    detector_reference: float = _DETECTOR.reference   # V: the CUSUM's k_ref
    detector_threshold: float = _DETECTOR.threshold   # V: the CUSUM's h
    detector_window: int = _DETECTOR.window           # samples the hand-over fits
    lock_window: int = _LOCK.window                   # N samples
    lock_low_count: int = _LOCK.low_count             # M of N below lock_level: lost
    lock_level: float = _LOCK.level                   # V
    lock_nis_alpha: float = _LOCK.nis_alpha           # the NIS band's tail probability
    lock_corroborate: int = _LOCK.corroborate         # low samples confirming a high NIS
    fade: float = _SUP.fade               # x noise: a dimmer mean in lock has faded (0: off)
    clip_prior: bool = _SUP.clip_prior    # start tracking: x0 with P0 clipped as a hand-over
    hold_samples: int = _SUP.hold_samples  # samples the EKF holds a loss before the search

    def __post_init__(self) -> None:
        """Check the settings by building the supervisor's; raise AlignmentError if bad."""
        if self.start not in STARTS:
            raise AlignmentError(f'pat.start must be one of {", ".join(STARTS)}, '
                                 f'got {self.start!r}')
        self.supervisor(noise=1.0, max_step=0.0, gate=0.0)

    def supervisor(self, *, noise: float, max_step: float, gate: float) -> SupervisorConfig:
        """
        Return the SupervisorConfig; noise (V, sigma of v), max_step and gate from the session.

        The hand-over fit's noise is sqrt(R_11) of the EKF, the sweep is clamped to the
        session's max_step, and the NIS went through the session's innovation gate.
        """
        return SupervisorConfig(
            scan=ScanConfig(speed=self.scan_speed, first=self.scan_first,
                            pitch=self.scan_pitch, half_width=self.scan_half_width,
                            cold_first=self.scan_cold_first),
            detector=DetectorConfig(reference=self.detector_reference,
                                    threshold=self.detector_threshold,
                                    window=self.detector_window),
            lock=LockConfig(window=self.lock_window, low_count=self.lock_low_count,
                            level=self.lock_level, nis_alpha=self.lock_nis_alpha,
                            gate=gate, corroborate=self.lock_corroborate),
            noise=noise, max_step=max_step, reacquire=self.reacquire, start=self.start,
            fade=self.fade, clip_prior=self.clip_prior, hold_samples=self.hold_samples)
