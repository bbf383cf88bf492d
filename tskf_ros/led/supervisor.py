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
Pointing, acquisition and tracking: a supervisor (acquiring, tracking, lost) around an aligner.

Not in Solanki et al. (2018), who track from a known prior.  Acquiring: the expanding
sweep of acquisition_scan until the CUSUM of light_detector sees light; hand-over: the
tracker starts from the least-squares fit of what the scan saw (the EKF's x and P set
from it, not from Table I's P0), the base turned onto the fitted bearing; tracking: the
aligner (scanning EKF of eq. (13)-(21), or a baseline of Section V) steers, watched by
lock_detector; lost: the sweep again, centred on the last good pointing angle and
widening; for the EKF after a hold (it keeps steering, tracking again once a window is
clean).  Vectorised over runs like the aligners.  Design: doc/pointing.md.
"""

from dataclasses import dataclass, field
import math
from typing import Optional, Union

import numpy as np

from tskf_ros.led.acquisition_scan import ExpandingSweep, Mask, ScanConfig
from tskf_ros.led.baselines import HillClimbing, ThreePointAveraging
from tskf_ros.led.intensity_model import AlignmentError, FloatArray, IncidenceResponse
from tskf_ros.led.light_detector import DetectorConfig, LightDetector
from tskf_ros.led.lock_detector import LockConfig, LockDetector, LockVerdict
from tskf_ros.led.scanning_ekf import as_measurement, Measurement, ScanningEKF

ACQUIRING, TRACKING, LOST = 0, 1, 2
STATES = ('acquiring', 'tracking', 'lost')
STARTS = ('acquiring', 'tracking')
# what a supervisor can steer: the scanning EKF with the P controller, or a baseline
Tracker = Union[ScanningEKF, HillClimbing, ThreePointAveraging]


@dataclass(frozen=True)
class SupervisorConfig:
    """The supervisor's search, detection and lock tests, and its actuation budget."""

    scan: ScanConfig = field(default_factory=ScanConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    lock: LockConfig = field(default_factory=LockConfig)
    noise: float = 1.0            # V: sigma of v the fit assumes (sqrt(R_11) of Table I)
    max_step: float = 45.0        # deg a command turns the base at most; 0: no limit
    reacquire: bool = True        # False: a loss restarts the tracker from x0, P0 in place
    start: str = 'acquiring'      # or 'tracking': from the tracker's own x0, P0
    level_fraction: float = 0.3   # the low level is at most this times the light in lock
    bright_samples: int = 20      # samples the light-in-lock average runs over
    inflate: float = 4.0          # the hand-over variances are this times the Fisher bound,
    x1_var: tuple[float, float] = (0.01, 4.0)      # V^2: clipped to this range
    angle_var: tuple[float, float] = (4.0, 25.0)   # deg^2: and this one
    # times `noise`: a light whose mean in lock is below this has faded (slowly: the mean
    # follows it) under the noise, and a low intensity is no evidence of a pointing loss:
    # the intensity test is off and the tracker keeps steering (0: never); a sudden block
    # leaves the mean high
    fade: float = 1.0
    # a known-start EKF's P0 gets the same clip: Table I's diag(100, 1000) throws runs off
    clip_prior: bool = True
    # the EKF holds a declared loss for this many samples before the sweep: it keeps
    # steering on its model and is tracking again after a full window with few low samples
    # (a block of the light leaves the pointing as it was); 0: sweep at once
    hold_samples: int = 100

    def __post_init__(self) -> None:
        """Check the supervisor's settings; raise AlignmentError with the reason."""
        if self.start not in STARTS:
            raise AlignmentError(f'start must be one of {STARTS}, got {self.start!r}')
        for name in ('noise', 'max_step', 'inflate', 'level_fraction', 'fade'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise AlignmentError(f'{name} must be >= 0, got {value}')
        if self.hold_samples < 0:
            raise AlignmentError(f'hold_samples must be >= 0, got {self.hold_samples}')
        if self.bright_samples < 1:
            raise AlignmentError(f'bright_samples must be >= 1, got {self.bright_samples}')
        if not self.noise > 0 or not self.inflate > 0:
            raise AlignmentError('noise and inflate must be > 0')
        for name in ('x1_var', 'angle_var'):
            lo, hi = getattr(self, name)
            if not (math.isfinite(hi) and 0.0 < lo <= hi):
                raise AlignmentError(f'{name} must be [lo, hi] with 0 < lo <= hi, '
                                     f'got {[lo, hi]}')
        if self.max_step > 0 and self.scan.speed > self.max_step:
            raise AlignmentError(f'the scan speed ({self.scan.speed:g} deg per sample) '
                                 f'exceeds max_step ({self.max_step:g} deg)')


class Supervisor:
    """
    The acquiring / tracking / lost machine of SupervisorConfig around `tracker`.

    `step(stamp, z)` has the Aligner interface (returns the turn per run); after it,
    `state` holds each run's state, `changed` the runs whose state changed, `declared`
    the runs whose loss was declared at this step, and `verdict` the lock tests.
    """

    def __init__(self, tracker: Tracker, config: SupervisorConfig = SupervisorConfig(),
                 response: Optional[IncidenceResponse] = None) -> None:
        if not isinstance(tracker, (ScanningEKF, HillClimbing, ThreePointAveraging)):
            raise AlignmentError(f'the supervisor cannot steer a {type(tracker).__name__}')
        self.tracker = tracker
        self.config = config
        self.response = response if response is not None else IncidenceResponse()
        self.runs = n = tracker.runs
        first = TRACKING if config.start == 'tracking' else ACQUIRING
        self.state = np.full(n, first, dtype=int)
        self.base = np.zeros(n)                  # deg turned since the start
        self.last_good = np.zeros(n)             # deg: pointing angle last seen in good lock
        self.sweep = ExpandingSweep(config.scan, n)
        self.finder = LightDetector(config.detector, self.response, n)
        self.lock = LockDetector(config.lock, n)
        self.changed: Mask = np.zeros(n, dtype=bool)
        self.resumed: Mask = np.zeros(n, dtype=bool)     # tracking again after a hold
        self.declared: Mask = np.zeros(n, dtype=bool)
        self.verdict: Optional[LockVerdict] = None
        # mean intensity in good lock (V; NaN: none yet) and how many samples it holds
        self.bright = np.full(n, np.nan)
        self.bright_count = np.zeros(n, dtype=int)
        self.tracked = np.zeros(n, dtype=int)       # samples steered by the tracker
        self.held = np.zeros(n, dtype=int)          # samples held since a loss (0: none)
        self.losses = np.zeros(n, dtype=int)
        self.handovers = np.zeros(n, dtype=int)
        if config.start == 'tracking' and config.clip_prior and self.is_ekf:
            self._clip_prior()

    @property
    def scan_offset(self) -> float:
        """Return the tracker's scan offset psi of the next sample (0 for the baselines)."""
        return self.tracker.scan_offset

    @property
    def steering(self) -> Mask:
        """Tell per run whether the tracker steers: tracking, or holding a declared loss."""
        return (self.state == TRACKING) | (self.held > 0)

    @property
    def is_ekf(self) -> bool:
        """Tell whether the tracker is the scanning EKF."""
        return isinstance(self.tracker, ScanningEKF)

    def acquire(self, mask: Optional[Mask] = None) -> None:
        """
        Force a new cold search around the current base angle (all runs, or those in mask).

        A run already searching keeps its search's centre: repeated requests restart the
        sweep there, and cannot walk it away, one leg at a time, from where it began.
        """
        mask = np.ones(self.runs, dtype=bool) if mask is None else np.asarray(mask, bool)
        old = self.state.copy()
        center = np.where(self.steering, self.base, self.sweep.center)
        self.state[mask] = ACQUIRING
        self.held[mask] = 0
        self.sweep.start(mask, center, cold=True)
        self.finder.reset(mask)
        self.changed = old != self.state

    def reconfigure(self, config: SupervisorConfig) -> None:
        """
        Take new settings in place (the session's gate, noise and max_step: its TUNABLE).

        The state, the sweep and the windows are kept; the NIS band follows the new gate.
        The sweep's and the detector's settings must be the ones in use (a change of
        those is a restart).
        """
        if (config.scan, config.detector) != (self.config.scan, self.config.detector) \
                or config.lock.window != self.config.lock.window:
            raise AlignmentError('the search and the window size change only by a restart')
        self.config = config
        self.lock.retune(config.lock)

    def correct_last_turn(self, delta: FloatArray) -> None:
        """
        Account for a base that turned delta more than the last command (clamped).

        A searching run whose turn was cut short (the joint limits) ends its leg there:
        a leg reaching beyond the limit would never end.
        """
        delta = np.asarray(delta, dtype=float)
        self.base = self.base + delta
        self.sweep.end_leg(~self.steering & (delta != 0.0))
        self.tracker.correct_last_turn(delta)

    def step(self, stamp: float, z: Measurement,
             tracker_z: Optional[Measurement] = None) -> FloatArray:
        """
        Take the measurement at `stamp` (NaN/None: missing); return the turn per run.

        tracker_z (None: z) is what the tracker may use, where it differs: a reading the
        tracker treats as missing (a negative one) is still dark to the detectors.
        """
        cfg = self.config
        z = as_measurement(z, self.runs)
        zt = z if tracker_z is None else as_measurement(tracker_z, self.runs)
        old = self.state.copy()
        tracking = old == TRACKING
        holding = self.held > 0
        steering = self.steering
        psi = self.tracker.scan_offset
        nis = np.full(self.runs, np.nan)
        if isinstance(self.tracker, ScanningEKF):
            # e_k = nu^2 / S of the new sample against the prior (before the step uses it)
            nis = self.tracker.innovation_distance(stamp, zt) ** 2
        inner = self.tracker.step(stamp, np.where(steering, zt, np.nan))
        # the mean in lock counts once it holds bright_samples (a mean of a few samples is no
        # evidence: right after a hand-over the dark samples of a block would make it small)
        known = self.bright_count >= cfg.bright_samples
        # the low level follows a light that dims: at most level_fraction of its mean in lock
        level = np.where(known, np.fmin(cfg.lock.level, cfg.level_fraction * self.bright),
                         cfg.lock.level)
        # faded: a mean in lock under the noise; no intensity test
        level = np.where(known & (self.bright < cfg.fade * cfg.noise), -np.inf, level)
        self.verdict = verdict = self.lock.update(z, nis, steering, level)
        # good lock: a full window since the hand-over (or a hold) with few low samples
        self.tracked = np.where(steering, self.tracked + 1, 0)
        steady = (self.tracked >= cfg.lock.window) & (verdict.low < max(cfg.lock.corroborate, 1))
        good = tracking & steady
        self.last_good = np.where(good, self.base - psi, self.last_good)
        seen = good & np.isfinite(z)
        self.bright_count[seen] = np.minimum(self.bright_count[seen] + 1, cfg.bright_samples)
        self.bright[seen] = np.where(np.isfinite(self.bright[seen]), self.bright[seen], 0.0) + (
            z[seen] - np.nan_to_num(self.bright[seen])) / self.bright_count[seen]
        searching = ~steering
        # searching again for a light that was dimmer than the detector's design
        scale = np.where(old == LOST, np.fmin(1.0, 0.5 * self.bright
                                              / cfg.detector.reference), 1.0)
        found = self.finder.update(z, self.base, searching, np.nan_to_num(scale, nan=1.0))
        turn = np.where(steering, inner, self.sweep.turn(self.base, searching))
        if np.any(found):
            turn[found] = self._hand_over(found)
        steered = steering.copy()           # the runs whose turn is the tracker's
        self.resumed = holding & steady
        if np.any(holding):
            self.held[holding] += 1
            self.state[self.resumed] = TRACKING
            self.held[self.resumed] = 0
            timeout = holding & ~steady & (self.held > cfg.hold_samples)
            self._search(timeout, turn)
            steered &= ~timeout
        lost = verdict.lost & tracking
        self.declared = lost
        if np.any(lost):
            self.losses[lost] += 1
            self.tracked[lost] = 0          # good lock needs a full window again
            if cfg.reacquire:
                self.state[lost] = LOST
                # only the EKF holds: its model of x1 and of the scan steers in the dark,
                # where a baseline's climb wanders (doc/pointing.md measures both)
                hold = lost & (self.is_ekf and cfg.hold_samples > 0)
                self.held[hold] = 1
                self.lock.reset(hold)
                self._search(lost & ~hold, turn)
                steered &= ~(lost & ~hold)
            else:
                self._restart_tracker(lost)
                self.lock.reset(lost)
        if cfg.max_step > 0:
            clamped = np.clip(turn, -cfg.max_step, cfg.max_step)
            if np.any(clamped != turn):
                self.tracker.correct_last_turn(np.where(steered, clamped - turn, 0.0))
            turn = clamped
        self.base = self.base + turn
        self.changed = old != self.state
        return turn

    def _search(self, mask: Mask, turn: FloatArray) -> None:
        """Start the sweep around the last good angle for the runs in mask; set their turn."""
        if np.any(mask):
            self.held[mask] = 0
            self.sweep.start(mask, self.last_good)
            self.finder.reset(mask)
            turn[mask] = self.sweep.turn(self.base, mask)[mask]

    def _hand_over(self, found: Mask) -> FloatArray:
        """Start tracking the runs in `found` from the scan's fit; return their turns."""
        cfg = self.config
        seen = self.finder.sighting(found, cfg.noise)
        psi_next = self.tracker.scan_offset
        base = self.base[found]
        # turn so that the next sample is taken at phi = psi_next, i.e. x2 = 0
        limit = cfg.max_step if cfg.max_step > 0 else np.inf
        turn = np.clip(seen.bearing + psi_next - base, -limit, limit)
        if isinstance(self.tracker, ScanningEKF):
            x = np.stack([seen.x1, base + turn - seen.bearing - psi_next], axis=-1)
            # x2 = const - c: var(x2) = var(c); the fit of a few noisy samples can be
            # ill-posed, so the variances are clipped and the correlation dropped
            P = np.zeros((x.shape[0], 2, 2))
            P[:, 0, 0] = np.clip(cfg.inflate * seen.P[:, 0, 0], *cfg.x1_var)
            P[:, 1, 1] = np.clip(cfg.inflate * seen.P[:, 1, 1], *cfg.angle_var)
            self.tracker.restart_runs(found, x, P)
        else:
            self.tracker.restart_runs(found)
        self.state[found] = TRACKING
        self.bright[found] = np.nan
        self.bright_count[found] = 0
        self.handovers[found] += 1
        self.lock.reset(found)
        return turn

    def _clip_prior(self) -> None:
        """Clip the EKF's starting variances to the hand-over's ranges, correlation dropped."""
        t = self.tracker
        assert isinstance(t, ScanningEKF)
        cfg = self.config
        P = np.zeros_like(t.P)
        P[:, 0, 0] = np.clip(t.P[:, 0, 0], *cfg.x1_var)
        P[:, 1, 1] = np.clip(t.P[:, 1, 1], *cfg.angle_var)
        t.restart_runs(np.ones(self.runs, dtype=bool), t.x.copy(), P)

    def _restart_tracker(self, mask: Mask) -> None:
        """Restart the tracker of the runs in mask from its initial state (x0, P0)."""
        t = self.tracker
        if isinstance(t, ScanningEKF):
            m = int(np.count_nonzero(mask))
            x0 = np.tile(np.asarray(t.config.x0, dtype=float), (m, 1))
            P0 = np.tile(np.asarray(t.config.P0, dtype=float), (m, 1, 1))
            t.restart_runs(mask, x0, P0)
        else:
            t.restart_runs(mask)
