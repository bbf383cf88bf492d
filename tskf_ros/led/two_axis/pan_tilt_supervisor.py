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
Pointing, acquisition and tracking in two axes: the supervisor around the conical-scan EKF.

The two-axis form of led.supervisor (not in Solanki et al. 2018, who track from a known
prior), with its states and tests: acquiring, the spiral search of spiral_search until
the CUSUM of spot_detector sees light; hand-over, the EKF starts from the least-squares
fit of what the spiral saw (x1 and d from it, the variances from its Fisher bound,
inflated and clipped), the boresight turned onto the fitted source plus the next scan
offset; tracking, the EKF steers, watched by lock_detector (the windowed NIS of the EKF's
own innovations and M of N intensities below lock.level, reused unchanged; not the
one-axis supervisor's level that follows the light in lock, which a hand-over onto the
wrong side of the light teaches to take the dark for the light); lost, the EKF holds a
declared loss for hold_samples (it keeps steering on its drift model; tracking again
after a full window with few low samples, half of it or more arrived), then the spiral
again, centred on the last mean pointing seen in good lock (a hand-over that never came
into good lock resumes the spiral where it stopped); a lock younger than hold_after is
not held, and a light that faded in lock (dim now, seen bright since the hand-over) is
held fade_hold samples, then, with fade_look, looked for by one spiral pass that follows
the drift model; a hold that runs out with the EKF's light under the detector's reference
(hold_dark: too dim for the search to find) is held on as a fade. The supervisor follows
the mount's joints [pan, tilt] from `joints0` as the mount does (joint_turn of each turn
at the tilt it is made at): a search is a pattern of directions on the sphere, and
tangent-plane turns do not add up to one (over a 30 deg spiral they would miss its centre
by tens of degrees). Vectorised over runs.
"""

from typing import Optional

import numpy as np

from tskf_ros.led.acquisition_scan import Mask
from tskf_ros.led.intensity_model import FloatArray
from tskf_ros.led.lock_detector import LockDetector, LockVerdict
from tskf_ros.led.scanning_ekf import as_measurement, Measurement
from tskf_ros.led.supervisor import ACQUIRING, LOST, STATES, TRACKING
from tskf_ros.led.two_axis.conical_ekf import ConicalScanEKF
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig
from tskf_ros.led.two_axis.pointing_geometry import (joint_turn, tangent_error,
                                                     turn_between)
from tskf_ros.led.two_axis.radial_response import RadialResponse
from tskf_ros.led.two_axis.spiral_search import SpiralSearch
from tskf_ros.led.two_axis.spot_detector import SpotDetector


class PanTiltSupervisor:
    """
    The acquiring / tracking / lost machine around a ConicalScanEKF, for every run.

    `step(stamp, z)` returns the tangent-plane turn (runs, 2); after it `state` holds each
    run's state (STATES), `declared` the runs whose loss was declared at this step.
    """

    STATES = STATES

    def __init__(self, tracker: ConicalScanEKF,
                 config: PanTiltSupervisorConfig = PanTiltSupervisorConfig(),
                 response: Optional[RadialResponse] = None, *,
                 joints0: tuple[float, float] = (0.0, 20.0)) -> None:
        self.tracker = tracker
        self.config = config
        self.response = response if response is not None else tracker.response
        self.runs = n = tracker.runs
        first = TRACKING if config.start == 'tracking' else ACQUIRING
        self.state = np.full(n, first, dtype=int)
        # the mount's joints [pan, tilt] (deg), and those of the tilt of the last turn
        self.joints = np.tile(np.asarray(joints0, dtype=float), (n, 1))
        self.tilt_of_turn = self.joints[:, 1].copy()
        self.last_good = self.joints.copy()      # mean pointing last seen in good lock
        self.spiral = SpiralSearch(config.spiral, n)
        self.spiral.start(np.ones(n, dtype=bool), self.joints)
        self.refine = SpiralSearch(config.refine or config.spiral, n)
        self.refine_samples = (config.refine.samples_to_cover(config.refine.reach)
                               if config.refine is not None else 0)
        self.finder = SpotDetector(config.detector, self.response, n, config.noise)
        self.lock = LockDetector(config.lock, n)
        self.changed: Mask = np.zeros(n, dtype=bool)
        self.declared: Mask = np.zeros(n, dtype=bool)
        self.resumed: Mask = np.zeros(n, dtype=bool)
        self.verdict: Optional[LockVerdict] = None
        self.tracked = np.zeros(n, dtype=int)
        self.held = np.zeros(n, dtype=int)
        self.losses = np.zeros(n, dtype=int)
        self.handovers = np.zeros(n, dtype=int)
        self.searched = np.zeros(n, dtype=int)      # samples since the search began
        self.pending = np.zeros(n, dtype=int)       # samples since the CUSUM saw light
        self.early = np.zeros(n, dtype=bool)        # the CUSUM saw light in this search
        self.locked = np.zeros(n, dtype=bool)       # in good lock since the hand-over
        self.hold_limit = np.full(n, config.hold_samples)   # samples the current hold lasts
        self.x1_lock = np.full(n, np.nan)           # x1hat in good lock, averaged
        self.fading = np.zeros(n, dtype=bool)       # the current hold is a fade hold
        self.x1_best = np.full(n, np.nan)           # the highest x1_lock since hand-over
        self.lock_age = np.zeros(n, dtype=int)      # samples in good lock since hand-over
        self.looking = np.zeros(n, dtype=bool)      # a fade hold's look is under way
        self.look_x = self.tracker.x.copy()         # the EKF when the look began
        self.look_P = self.tracker.P.copy()

    @property
    def scan_offset(self) -> FloatArray:
        """Return the EKF's scan offset of the next sample (2,), or (runs, 2) per run."""
        return self.tracker.scan_offset

    @property
    def steering(self) -> Mask:
        """Tell per run whether the EKF steers: tracking, or holding a declared loss."""
        return (self.state == TRACKING) | (self.held > 0)

    @property
    def x(self) -> FloatArray:
        """Return the EKF's posterior (runs, 5)."""
        return self.tracker.x

    @property
    def P(self) -> FloatArray:
        """Return the EKF's posterior covariance (runs, 5, 5)."""
        return self.tracker.P

    def acquire(self, mask: Optional[Mask] = None) -> None:
        """Force a new cold search around the current boresight (all runs, or mask)."""
        mask = np.ones(self.runs, dtype=bool) if mask is None else np.asarray(mask, bool)
        old = self.state.copy()
        center = np.where(self.steering[:, None], self.joints, self.spiral.center)
        self.state[mask] = ACQUIRING
        self.held[mask] = 0
        self.spiral.start(mask, center)
        self.finder.reset(mask)
        self.searched[mask] = self.pending[mask] = 0
        self.early[mask] = False
        self.looking[mask] = False
        self.changed = old != self.state

    def correct_last_turn(self, delta: FloatArray) -> None:
        """Account for a mount that turned delta (runs, 2) more than the last command."""
        delta = np.asarray(delta, dtype=float)
        self.joints = self.joints + joint_turn(delta, self.tilt_of_turn)
        self.tracker.correct_last_turn(np.where(self.steering[:, None], delta, 0.0))

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Take the sample at `stamp` (NaN/None: missing); return the turn (runs, 2)."""
        cfg = self.config
        z = as_measurement(z, self.runs)
        old = self.state.copy()
        tracking = old == TRACKING
        holding = self.held > 0
        steering = self.steering
        s_now = self.tracker.scan_offset
        self.tracker.tilt = self.joints[:, 1].copy()     # the mount's, which the search moves
        inner = self.tracker.step(stamp, np.where(steering, z, np.nan))
        nis = np.where(steering, self.tracker.nis, np.nan)
        self.verdict = verdict = self.lock.update(z, nis, steering)
        self.tracked = np.where(steering, self.tracked + 1, 0)
        # few low samples of a window at least half full (the NIS test's rule): a blocked
        # beam whose dark readings arrive as missing (a node's negative_is_missing) leaves
        # a few low samples, which are not few of many
        steady = ((self.tracked >= cfg.lock.window)
                  & (verdict.low < max(cfg.lock.corroborate, 1))
                  & (self.lock.counted >= (cfg.lock.window + 1) // 2))
        good = tracking & steady
        mean = self.joints - joint_turn(s_now, self.joints[:, 1])
        self.last_good = np.where(good[:, None], mean, self.last_good)
        self.locked |= good
        self.lock_age = np.where(good, self.lock_age + 1, self.lock_age)
        x1 = self.tracker.x[:, 0]
        # an exponential average over about a second (alpha = 1/20), only in good lock
        self.x1_lock = np.where(good, np.where(np.isfinite(self.x1_lock),
                                               self.x1_lock + (x1 - self.x1_lock) / 20.0, x1),
                                self.x1_lock)
        self.x1_best = np.fmax(self.x1_best, self.x1_lock)
        searching = ~steering
        seen_light = self.finder.update(z, self.joints, searching)
        self.searched = np.where(searching, self.searched + 1, 0)
        if cfg.early_light:
            # light seen before min_samples is kept until then (the CUSUM falls again once
            # the spiral has passed the light, and a light near the start is crossed early)
            self.early = np.where(searching, self.early | seen_light, False)
            seen_light = self.early & (self.pending == 0)
        seen_light &= self.searched >= cfg.min_samples
        self.pending = np.where(searching & ((self.pending > 0) | seen_light),
                                self.pending + 1, 0)
        if cfg.refine is not None:
            settled = self.pending == cfg.settle + 1
            if np.any(settled):
                self.refine.start(settled, self._scatter(settled,
                                                         self.finder.sighting(settled,
                                                                              cfg.noise).center))
        found = self.pending > cfg.settle + self.refine_samples
        fine = searching & (self.pending > cfg.settle) & (cfg.refine is not None)
        search = (self.spiral.turn(self.joints, searching & ~fine)
                  + self.refine.turn(self.joints, fine))
        turn = np.where(steering[:, None], inner, search)
        # a look that went round its spiral without seeing light: back to the hold
        back = self.looking & searching & (self.spiral.spirals > 0) & (self.pending == 0)
        if np.any(back):
            turn[back] = self._back_to_hold(back)
        if np.any(found):
            turn[found] = self._hand_over(found)
        steered = steering.copy()
        self.resumed = holding & steady
        if np.any(holding):
            self.held[holding] += 1
            self.state[self.resumed] = TRACKING
            self.held[self.resumed] = 0
            timeout = holding & ~steady & (self.held > self.hold_limit)
            if cfg.holds_dark:
                # a light too dim for the search to find: held on as a fade
                dark = timeout & ~self.fading & (self.tracker.x[:, 0] * self.response.peak
                                                 < cfg.detector.reference)
                self.hold_limit = np.where(dark, cfg.fade_limit,
                                           self.hold_limit)
                self.fading |= dark
                timeout &= ~dark
            look = timeout & self.fading & (cfg.fade_look > 0)
            self._look(look, turn, mean)
            self._search(timeout & ~look, turn)
            steered &= ~timeout
        dim = self.tracker.x[:, 0] * self.response.peak < cfg.min_peak
        lost = (verdict.lost | dim) & tracking
        self.declared = lost
        if np.any(lost):
            self.losses[lost] += 1
            self.tracked[lost] = 0
            self.state[lost] = LOST
            # a hand-over that never came into good lock, or held it less than hold_after
            # samples, was onto no light or a fit off it: search again at once
            hold = (lost & self.locked & (self.lock_age >= cfg.hold_after)
                    & (cfg.hold_samples > 0))
            # faded: dim now, and seen at fade_peak or brighter in this lock (a lock that
            # never saw the light bright may be an EKF that explains its own error by x1)
            peak = self.response.peak
            faded = ((self.x1_lock * peak < cfg.fade_peak)
                     & ((self.x1_best * peak >= cfg.fade_peak) | (not cfg.fade_seen)))
            self.hold_limit = np.where(hold & faded, cfg.fade_limit,
                                       np.where(hold, cfg.hold_samples, self.hold_limit))
            self.fading = np.where(lost, hold & faded, self.fading)
            self.held[hold] = 1
            self.lock.reset(hold)
            self._search(lost & ~hold, turn)
            steered &= ~(lost & ~hold)
        if cfg.max_step > 0:
            clamped = np.clip(turn, -cfg.max_step, cfg.max_step)
            if np.any(clamped != turn):
                self.tracker.correct_last_turn(np.where(steered[:, None], clamped - turn, 0.0))
            turn = clamped
        self.tilt_of_turn = self.joints[:, 1].copy()
        self.joints = self.joints + joint_turn(turn, self.joints[:, 1])
        self.changed = old != self.state
        return turn

    def _search(self, mask: Mask, turn: FloatArray, center: Optional[FloatArray] = None,
                rate: Optional[FloatArray] = None, reach: Optional[float] = None) -> None:
        """Start the spiral for the runs in mask (centre: None, see below); set turn."""
        if np.any(mask):
            self.held[mask] = 0
            self.looking[mask] = False
            # around the last good pointing; after a hand-over onto no light, around the
            # search's own centre again (or on from where it stopped: resume)
            resumed = np.zeros(self.runs, dtype=bool)
            if center is None:
                center = np.where(self.locked[:, None], self.last_good, self.spiral.center)
                if self.config.resume:
                    resumed = mask & ~self.locked & (self.handovers > 0)
            self.spiral.start(mask & ~resumed, center, rate, reach)
            self.finder.reset(mask)
            self.searched[mask] = self.pending[mask] = 0
            self.early[mask] = False
            turn[mask] = self.spiral.turn(self.joints, mask)[mask]

    def _look(self, mask: Mask, turn: FloatArray, mean: FloatArray) -> None:
        """Start a look for the runs in mask: one spiral pass that follows the drift model."""
        if np.any(mask):
            self.look_x[mask] = self.tracker.x[mask]
            self.look_P[mask] = self.tracker.P[mask]
            # around the hold's pointing (the mean pointing of this sample), the centre
            # moving on as the hold would have steered, -bhat per step
            self._search(mask, turn, mean, -self.tracker.x[:, 3:5], self.config.fade_look)
            self.looking[mask] = True

    def _back_to_hold(self, back: Mask) -> FloatArray:
        """Turn the runs in `back` onto the look's centre and hold again; return the turns."""
        cfg = self.config
        s_next = self._offset(back)
        center = self.spiral.center[back]
        # the joints whose mean pointing (the joints less the scan offset, at their tilt)
        # is the centre
        target = center + joint_turn(s_next, center[:, 1] + s_next[:, 1])
        limit = cfg.max_step if cfg.max_step > 0 else np.inf
        turn = np.clip(turn_between(self.joints[back], target), -limit, limit)
        # the EKF as the look found it, its variances grown by the samples it looked
        grown = self.searched[back, None, None] * self.tracker.Q
        self.tracker.restart_runs(back, self.look_x[back], self.look_P[back] + grown)
        self.looking[back] = False
        self.held[back] = 1
        self.hold_limit[back] = cfg.fade_limit
        self.tracked[back] = 0
        self.lock.reset(back)
        return turn

    def _offset(self, mask: Mask) -> FloatArray:
        """Return the EKF's next scan offset of the runs in mask (m, 2)."""
        return np.broadcast_to(self.tracker.scan_offset, (self.runs, 2))[mask]

    def _scatter(self, mask: Mask, rows: FloatArray) -> FloatArray:
        """Return a (runs, 2) array with `rows` at the runs in mask, the joints elsewhere."""
        out = self.joints.copy()
        out[mask] = rows
        return out

    def _hand_over(self, found: Mask) -> FloatArray:
        """Start tracking the runs in `found` from the spiral's fit; return their turns."""
        cfg = self.config
        seen = self.finder.sighting(found, cfg.noise)
        s_next = self._offset(found)
        joints = self.joints[found]
        source = seen.center
        limit = cfg.max_step if cfg.max_step > 0 else np.inf
        # turn so that the next sample is taken with the mean pointing on the fit: d = 0
        target = source + joint_turn(s_next, source[:, 1])
        turn = np.clip(turn_between(joints, target), -limit, limit)
        after = joints + joint_turn(turn, joints[:, 1])
        mean = after - joint_turn(s_next, after[:, 1])
        m = int(np.count_nonzero(found))
        x = np.zeros((m, 5))
        x[:, 0] = seen.x1
        x[:, 1:3] = tangent_error(mean[:, 0], mean[:, 1], source[:, 0], source[:, 1])
        P = np.zeros((m, 5, 5))
        P[:, 0, 0] = np.clip(cfg.inflate * seen.P[:, 0, 0], *cfg.x1_var)
        for i in (1, 2):
            P[:, i, i] = np.clip(cfg.inflate * seen.P[:, i, i], *cfg.angle_var)
        P0 = self.tracker.config.P0
        P[:, 3, 3], P[:, 4, 4] = P0[3], P0[4]
        self.tracker.restart_runs(found, x, P)
        self.state[found] = TRACKING
        self.handovers[found] += 1
        self.pending[found] = 0
        self.looking[found] = False
        self.locked[found] = False
        self.x1_best[found] = np.nan
        self.lock_age[found] = 0
        self.x1_lock[found] = np.nan
        self.lock.reset(found)
        return turn
