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
A streaming two-axis alignment session: stamped intensities in, [pan, tilt] commands out.

The two-axis form of led.alignment_session, for the alignment node: each sample is one
step of a two-axis aligner (aligners.make_two_axis_aligner, one run), predicted over
mu = elapsed / dt from the stamps; its tangent-plane turn is executed as a joint turn
at the commanded tilt (pointing_geometry.joint_turn) and added to the commanded joints.
A stamp that is unset, repeated or older than the last is rejected; a jump backward
beyond max_backward restarts the aligner; a reading that is None or not finite is a
missing sample (the filter predicts over it).  Angles in degrees, intensities in volts.
"""

from dataclasses import dataclass, field
import math
from typing import Optional

import numpy as np

from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.led.intensity_model import AlignmentError, FloatArray
from tskf_ros.led.scanning_ekf import PAPER_DT
from tskf_ros.led.two_axis.aligners import make_two_axis_aligner, METHODS, STARTS
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig
from tskf_ros.led.two_axis.pan_tilt_link import (PanTiltLink, PanTiltLinkConfig, PanTiltSample,
                                                 Seed)
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig
from tskf_ros.led.two_axis.pointing_geometry import joint_turn, MAX_ELEVATION


@dataclass(frozen=True)
class PanTiltSessionConfig:
    """The session's aligner and its limits; angles in degrees, time in s."""

    method: str = 'conical_ekf'              # one of aligners.METHODS
    start: str = 'tracking'                  # or 'acquiring' (a cold search, with pat)
    dt: float = PAPER_DT                     # nominal sample interval
    noise: float = 0.2                       # V: sigma of v the filter assumes
    joints0: tuple[float, float] = (0.0, 20.0)   # [pan, tilt] at the start
    max_step: float = 45.0                   # deg a command turns each axis at most; 0: any
    tilt_limits: tuple[float, float] = (-MAX_ELEVATION, MAX_ELEVATION)
    max_backward: float = 1.0                # s: an older stamp within this is stale
    state_limit: float = 1e4                 # |x| or sqrt(trace P) beyond: restart
    # the conical-scan EKF's settings (its noise and dt are replaced by the two above) and
    # the supervisor's (its start and noise replaced: make_two_axis_aligner)
    ekf: ConicalEKFConfig = field(default_factory=ConicalEKFConfig)
    supervisor: PanTiltSupervisorConfig = field(default_factory=PanTiltSupervisorConfig)

    def __post_init__(self) -> None:
        """Check the settings (building the aligner once); raise AlignmentError if bad."""
        if self.method not in METHODS:
            raise AlignmentError(f'method must be one of {", ".join(METHODS)}, '
                                 f'got {self.method!r}')
        if self.start not in STARTS:
            raise AlignmentError(f'start must be one of {", ".join(STARTS)}, got {self.start!r}')
        values = (self.dt, self.noise, *self.joints0, self.max_step, *self.tilt_limits,
                  self.max_backward, self.state_limit)
        if len(self.joints0) != 2 or not all(math.isfinite(v) for v in values):
            raise AlignmentError('joints0 must be [pan, tilt]; every setting must be finite')
        if not (self.dt > 0 and self.noise > 0 and self.state_limit > 0):
            raise AlignmentError('dt, noise and state_limit must be > 0')
        if self.max_step < 0 or self.max_backward < 0:
            raise AlignmentError('max_step and max_backward must be >= 0')
        # as one axis: the filter's start, and one nominal step from it, within state_limit
        # (else every sample would restart it)
        if max(abs(v) for v in self.ekf.x0) > self.state_limit:
            raise AlignmentError(f'x0 {list(self.ekf.x0)} is beyond state_limit '
                                 f'{self.state_limit:g}')
        spread = math.sqrt(sum(self.ekf.P0) + sum(self.ekf.Q))
        if spread > self.state_limit:
            raise AlignmentError(f'P0 + Q (one step) has sqrt(trace) {spread:.3g} beyond '
                                 f'state_limit {self.state_limit:g}')
        lo, hi = self.tilt_limits
        if not -MAX_ELEVATION <= lo < hi <= MAX_ELEVATION:
            raise AlignmentError(f'tilt_limits must be [lo, hi] with lo < hi within '
                                 f'+-{MAX_ELEVATION:g} deg, got {list(self.tilt_limits)}')
        if not lo <= self.joints0[1] <= hi:
            raise AlignmentError(f"the start tilt {self.joints0[1]:g} deg (joints0, the node's "
                                 f'pan_tilt.initial) is outside tilt_limits '
                                 f'{list(self.tilt_limits)}')

    def make_aligner(self, joints: Optional[tuple[float, float]] = None) -> object:
        """Build the configured aligner for one run, its mount at joints (None: joints0)."""
        return make_two_axis_aligner(self.method, runs=1, noise=self.noise, dt=self.dt,
                                     start=self.start, ekf=self.ekf,
                                     supervisor=self.supervisor,
                                     joints0=self.joints0 if joints is None else joints)


@dataclass(frozen=True)
class PanTiltEstimate:
    """The filter's estimate: intensity factor (V), the two errors (deg), and their P."""

    intensity: float
    error: tuple[float, float]      # [d_c, d_e]: cross-elevation and elevation error
    covariance: FloatArray          # (3, 3) of [x1, d_c, d_e]
    x: FloatArray                   # the whole state
    P: FloatArray                   # and its covariance
    states: tuple[str, ...]         # the names of x


@dataclass(frozen=True)
class PanTiltOutcome:
    """What one sample did, and what to publish."""

    status: str                                  # 'used', 'missing', 'rejected', 'reset'
    reason: str = ''
    message: str = ''
    stamp_ns: int = 0
    command: Optional[tuple[float, float]] = None    # absolute [pan, tilt] (deg)
    turn: Optional[tuple[float, float]] = None       # tangent-plane turn (deg)
    estimate: Optional[PanTiltEstimate] = None       # after the update (None: searching)
    state: str = 'disabled'                          # acquiring, tracking, lost, disabled


class PanTiltSession:
    """One two-axis aligner fed from a stream of stamped intensities; see the module doc."""

    def __init__(self, config: PanTiltSessionConfig = PanTiltSessionConfig(), *,
                 earlier_failures: int = 0) -> None:
        """Start the aligner; earlier_failures: smoothing failures of a session this replaces."""
        self.config = config
        self.joints = np.asarray(config.joints0, dtype=float).copy()
        self.resets = 0
        # smoothing failures of the aligners restarted since (and of a session replaced)
        self.earlier_failures = int(earlier_failures)
        self._restart()

    def _restart(self) -> None:
        if hasattr(self, 'aligner'):
            self.earlier_failures = self.smoothing_failures
        self.aligner = self.config.make_aligner((float(self.joints[0]),
                                                 float(self.joints[1])))
        self.origin_ns: Optional[int] = None
        self.last_ns: Optional[int] = None

    @property
    def tracker(self) -> object:
        """Return the filter that tracks (inside the supervisor, if there is one)."""
        return getattr(self.aligner, 'tracker', self.aligner)

    @property
    def smoothing_failures(self) -> int:
        """Return the windows whose smoothing failed (the filter's estimate kept), all told."""
        return self.earlier_failures + int(getattr(self.tracker, 'smoothing_failures', 0))

    @property
    def state(self) -> str:
        """Return the pointing state: the supervisor's, or 'disabled' without one."""
        names = getattr(self.aligner, 'STATES', None)
        if names is None:
            return 'disabled'
        return str(names[int(getattr(self.aligner, 'state')[0])])

    @property
    def steering(self) -> bool:
        """Tell whether the filter steers (no supervisor, or tracking or holding a loss)."""
        mask = getattr(self.aligner, 'steering', None)
        return True if mask is None else bool(mask[0])

    def reset(self) -> None:
        """Restart the aligner from its prior; the joints stay where they are."""
        self.resets += 1
        self._restart()

    def acquire(self) -> bool:
        """Force a new cold search around the joints; False without a supervisor."""
        acquire = getattr(self.aligner, 'acquire', None)
        if acquire is None:
            return False
        acquire()
        return True

    def estimate(self) -> Optional[PanTiltEstimate]:
        """Return the filter's posterior, or None while a supervisor searches."""
        t = self.tracker
        if not self.steering:
            return None
        x = np.array(getattr(t, 'x')[0], dtype=float)
        P = np.array(getattr(t, 'P')[0], dtype=float)
        P = (P + P.T) / 2
        return PanTiltEstimate(float(x[0]), (float(x[1]), float(x[2])), P[:3, :3].copy(),
                               x, P, tuple(getattr(t, 'states')))

    def add(self, stamp_ns: int, z: Optional[float]) -> PanTiltOutcome:
        """Take one sample (stamp in ns, intensity in V or None: missing); say what it did."""
        cfg = self.config
        stamp_ns = int(stamp_ns)
        if stamp_ns <= 0:
            return self._reject('zero_stamp', stamp_ns, 'the header stamp is unset (0)')
        if stamp_ns > MAX_STAMP_NS:
            return self._reject('stamp_range', stamp_ns, f'stamp {stamp_ns} ns is beyond '
                                'what a ROS message can hold')
        status, reason, message = 'used', '', ''
        last = self.last_ns
        if last is not None and stamp_ns == last:
            return self._reject('duplicate', stamp_ns, 'the stamp repeats the last')
        if last is not None and stamp_ns < last:
            back = (last - stamp_ns) / NS
            if back <= cfg.max_backward:
                return self._reject('stale', stamp_ns, f'stamp is {back:.3f} s older than '
                                    'the last')
            self.reset()
            status, reason = 'reset', 'backward_jump'
            message = f'stamp jumped {back:.3f} s backward (> max_backward); restarted'
        value = math.nan if z is None else float(z)
        if not math.isfinite(value) and status == 'used':
            status, reason, message = 'missing', 'non_finite', f'intensity {z} is not finite'
        if self.origin_ns is None:
            self.origin_ns = stamp_ns
        self.last_ns = stamp_ns
        t = (stamp_ns - self.origin_ns) / NS
        try:
            with np.errstate(over='ignore', invalid='ignore'):
                turn = np.asarray(getattr(self.aligner, 'step')(t, value),
                                  dtype=float).reshape(2)
        except (AlignmentError, np.linalg.LinAlgError) as exc:
            return self._fail(stamp_ns, str(exc))
        estimate = self.estimate()
        if estimate is not None:
            if not (np.all(np.isfinite(estimate.x)) and np.all(np.isfinite(estimate.P))):
                return self._fail(stamp_ns, 'the filter estimate is not finite')
            big = max(float(np.max(np.abs(estimate.x))),
                      math.sqrt(max(float(np.trace(estimate.P)), 0.0)))
            if big > cfg.state_limit:
                return self._fail(stamp_ns, f'filter state or covariance {big:.3g} beyond '
                                  f'state_limit {cfg.state_limit:g}')
        if not np.all(np.isfinite(turn)):
            return self._fail(stamp_ns, f'the turn {turn.tolist()} is not finite')
        applied = self._clamp(turn)
        correct = getattr(self.aligner, 'correct_last_turn', None)
        if correct is not None and np.any(applied != turn):
            correct((applied - turn)[None, :])
        self.joints = self.joints + joint_turn(applied, self.joints[1])
        return PanTiltOutcome(status, reason, message, stamp_ns,
                              (float(self.joints[0]), float(self.joints[1])),
                              (float(applied[0]), float(applied[1])), estimate, self.state)

    def _clamp(self, turn: FloatArray) -> FloatArray:
        """Return the turn limited to max_step per axis and the tilt to tilt_limits."""
        cfg = self.config
        if cfg.max_step > 0:
            turn = np.clip(turn, -cfg.max_step, cfg.max_step)
        lo, hi = cfg.tilt_limits
        tilt = min(max(self.joints[1] + turn[1], lo), hi)
        return np.array([turn[0], tilt - self.joints[1]])

    def _reject(self, reason: str, stamp_ns: int, message: str) -> PanTiltOutcome:
        return PanTiltOutcome('rejected', reason, message, stamp_ns, state=self.state)

    def _fail(self, stamp_ns: int, message: str) -> PanTiltOutcome:
        """Restart the aligner after a failed step; nothing is commanded for this sample."""
        self.reset()
        return self._reject('filter_error', stamp_ns, f'{message}; aligner restarted')


@dataclass
class PanTiltLoop:
    """A closed-loop run: the link's samples and the session's outcomes (None: dropped)."""

    samples: list[PanTiltSample]
    outcomes: list[Optional[PanTiltOutcome]]

    def theta(self) -> FloatArray:
        """Return the exact off-axis angle of the boresight per sample (deg)."""
        return np.array([float(s.theta[0]) for s in self.samples])


def pan_tilt_closed_loop(link: PanTiltLinkConfig, session: PanTiltSession, steps: int, *,
                         seed: Seed = 0, start_ns: int = 1_000_000_000) -> PanTiltLoop:
    """
    Run `steps` samples of a one-run PanTiltLink against a session, as the two nodes do.

    Sample k is stamped start_ns + its time in ns; a delivered sample goes to session.add
    and its [pan, tilt] command is applied before the next sample; a dropped one never
    reaches the session.  The session must start at the link's joints (0, elevation0).
    This is the reference the node tests compare against.
    """
    plant = PanTiltLink(link, runs=1, seed=seed)
    if not np.allclose(session.joints, plant.joints[0]):
        raise AlignmentError(f'the session starts at {session.joints.tolist()}, the link at '
                             f'{plant.joints[0].tolist()}')
    samples: list[PanTiltSample] = []
    outcomes: list[Optional[PanTiltOutcome]] = []
    for _ in range(int(steps)):
        s = plant.sample()
        samples.append(s)
        if bool(s.missing[0]):
            outcomes.append(None)
            continue
        out = session.add(start_ns + int(round(s.t * NS)), float(s.reading[0]))
        outcomes.append(out)
        if out.command is not None:
            plant.command(np.array(out.command))
    return PanTiltLoop(samples, outcomes)
