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
A streaming alignment session: stamped intensity samples in, base position commands out.

Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018): each sample is one iteration k of an
aligner of tskf_ros.led, the scanning EKF of Section IV (eq. (13)-(21), predicted over
mu = elapsed / dt; its turn is u_k + psi_{k+1} - psi_k) or a baseline of Section V,
with pat.enabled inside the acquiring / tracking / lost supervisor (not in the paper,
doc/pointing.md); the turn is added to the base angle.  What happens to bad input:
doc/design/alignment.md.
"""

from collections import Counter
from dataclasses import dataclass, field, fields
import math
from typing import NamedTuple, Optional, Union

import numpy as np

from tskf_ros import led
from tskf_ros.core.diagnostic_status import (expected_frequency, FrequencyParams, InputStream,
                                             Status)
from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.led.alignment_config import AlignmentConfig, TUNABLE
from tskf_ros.led.alignment_diagnostics import aligner_status, pointing_status, time_scale
from tskf_ros.led.intensity_model import FloatArray
from tskf_ros.led.pointing_stats import PointingStats, Transition
from tskf_ros.led.supervisor import STATES, Supervisor

GAP_FACTOR = 1.5        # an interval longer than this many dt is a gap (samples missing)
MISSING_REASONS = ('non_finite', 'negative', 'out_of_range', 'gated')
REJECT_REASONS = ('zero_stamp', 'stamp_range', 'duplicate', 'stale', 'filter_error')
RESET_REASONS = ('backward_jump', 'clock_jump', 'reconfigured', 'filter_error',
                 'state_health')


class Estimate(NamedTuple):
    """An EKF estimate of one run: x = [x1 (V), x2 (deg)] and its 2 x 2 covariance P."""

    x: FloatArray
    P: FloatArray


@dataclass
class AlignOutcome:
    """What one sample did, and what to publish (angles in degrees)."""

    status: str                          # 'used', 'missing', 'rejected' or 'reset'
    reason: str = ''
    message: str = ''
    stamp_ns: int = 0
    mu: float = 0.0                      # s from the run's previous sample (0: its first)
    command: Optional[float] = None      # absolute base position command (deg)
    turn: Optional[float] = None         # the aligner's motor command (deg)
    prior: Optional[Estimate] = None     # EKF (x, P) before the update, x2 in deg
    posterior: Optional[Estimate] = None     # EKF (x, P) after the update


@dataclass
class AlignStats:
    """Counters for diagnostics."""

    # alike in shape to the estimator session's Stats, but other counters
    received: int = 0
    paused: int = 0                      # received while the loop was paused
    used: int = 0
    commands: int = 0
    missing: Counter[str] = field(default_factory=Counter)
    rejected: Counter[str] = field(default_factory=Counter)
    resets: Counter[str] = field(default_factory=Counter)
    gaps: int = 0
    gap_max: float = 0.0
    # samples the stamps say never came (a gap of mu dt: round(mu) - 1 of them), wherever
    # they were lost: in transport, in a full subscription queue (bursts), at the sensor
    missed: int = 0
    # the middleware's count of intensities lost in transport (the node's message_lost
    # event: a gap in the publisher's sequence, not a queue overflow)
    messages_lost: int = 0
    mu_current: float = 0.0
    mu_max: float = 0.0
    singular: int = 0
    clamped: int = 0
    last_stamp_ns: int = 0
    # since the last diagnostics report
    gaps_over_bound: int = 0
    bad_since: int = 0

    def record_interval(self, interval: float, dt: float, max_gap: float) -> None:
        """Count an interval between stamps: a gap when it is over GAP_FACTOR dt."""
        mu = interval / dt
        self.mu_current = mu
        self.mu_max = max(self.mu_max, mu)
        if mu > GAP_FACTOR:
            self.gaps += 1
            self.missed += max(int(round(mu)) - 1, 0)
            self.gap_max = max(self.gap_max, interval)
            if interval > max_gap:
                self.gaps_over_bound += 1


class AlignmentSession:
    """One aligner fed from a stream of stamped intensity samples; see the module docstring."""

    def __init__(self, config: AlignmentConfig) -> None:
        self.config = config
        self.stats = AlignStats()
        self.base = float(config.base_initial)
        self.health_error = ''          # why the aligner restarted itself
        self.paused = False             # the node's ~/enable false: samples are not used
        self.input = InputStream(_frequency(config))
        self.pointing = PointingStats()
        self._restart('start')

    def _restart(self, reason: str) -> None:
        tracker = self._tracker = self.config.make_aligner()
        self.supervisor: Optional[Supervisor] = None
        self.aligner: Union[led.AnyAligner, Supervisor] = tracker
        if self.config.pat.enabled:
            if isinstance(tracker, led.LQGAligner):     # AlignmentConfig refuses it too
                raise led.AlignmentError('the supervisor cannot steer the LQG aligner')
            self.supervisor = Supervisor(tracker, self.config.supervisor(),
                                         self.config.response())
            self.aligner = self.supervisor
            self.pointing.enter(STATES[int(self.supervisor.state[0])], reason,
                                self.stats.last_stamp_ns or None)
        else:
            self.pointing.enter('disabled', reason, self.stats.last_stamp_ns or None)
        self.origin_ns: Optional[int] = None
        self.last_ns: Optional[int] = None

    @property
    def tracker(self) -> led.AnyAligner:
        """Return the aligner that tracks (inside the supervisor, if there is one)."""
        return self._tracker

    @property
    def ekf(self) -> Optional[led.ScanningEKF]:
        """Return the tracker if it is the scanning EKF (the one with an estimate), else None."""
        t = self.tracker
        return t if isinstance(t, led.ScanningEKF) else None

    @property
    def is_ekf(self) -> bool:
        """Tell whether the tracker is the scanning EKF (the one with an estimate)."""
        return isinstance(self.tracker, led.ScanningEKF)

    @property
    def pat_state(self) -> str:
        """Return the supervisor's state (acquiring, tracking, lost); disabled without one."""
        return self.pointing.state

    @property
    def tracking(self) -> bool:
        """Tell whether the tracker steers: always without a supervisor, else tracking or held."""
        return self.supervisor is None or bool(self.supervisor.steering[0])

    def acquire(self) -> bool:
        """Force a new cold search around the base (~/acquire); False without a supervisor."""
        if self.supervisor is None:
            return False
        self.supervisor.acquire()
        self.pointing.requests += 1
        self.pointing.enter('acquiring', 'acquire requested', self.stats.last_stamp_ns or None)
        return True

    def take_transitions(self) -> list[Transition]:
        """Return the state transitions since the last call, oldest first, and forget them."""
        return self.pointing.take()

    # -- public API -----------------------------------------------------------------------

    def add(self, stamp_ns: int, z: float, *, now_ns: Optional[int] = None) -> AlignOutcome:
        """Take one sample (stamp in ns, intensity in V; receiver clock now); say what it did."""
        st, cfg = self.stats, self.config
        st.received += 1
        stamp_ns = int(stamp_ns)
        if now_ns is not None:
            self.input.note(stamp_ns, now_ns)
        if stamp_ns <= 0:
            return self._reject('zero_stamp', stamp_ns, 'the header stamp is unset (0)')
        if stamp_ns > MAX_STAMP_NS:
            return self._reject('stamp_range', stamp_ns, f'stamp {stamp_ns} ns is beyond what '
                                'a ROS message can hold (sec is an int32)')
        status, reason, message = 'used', '', ''
        last = self.last_ns
        if last is not None and stamp_ns == last:
            return self._reject('duplicate', stamp_ns,
                                f'stamp {stamp_ns / NS:.9f} s repeats the last')
        if last is not None and stamp_ns < last:
            back = (last - stamp_ns) / NS
            if back <= cfg.max_backward:
                return self._reject('stale', stamp_ns, f'stamp {stamp_ns / NS:.9f} s is '
                                    f'{back:.3f} s older than the last')
            self.reset('backward_jump')
            status, reason = 'reset', 'backward_jump'
            message = f'stamp jumped {back:.3f} s backward (> max_backward); restarted'
            last = None
        z = float(z)
        ekf = self.ekf
        # the tracker uses this sample (a searching supervisor steps it with no measurement)
        tracking = self.tracking
        if not math.isfinite(z):
            status, reason, message = 'missing', 'non_finite', f'intensity {z} is not finite'
        elif abs(z) > cfg.state_limit:
            # no light the aligner can follow (x1 would pass state_limit): not even dark
            status, reason = 'missing', 'out_of_range'
            message = f'intensity {z:g} V is beyond state_limit {cfg.state_limit:g} V'
        elif z < 0 and cfg.negative_is_missing:
            status, reason, message = 'missing', 'negative', f'intensity {z:g} V < 0'
        elif cfg.intensity_range and not (
                cfg.intensity_range[0] <= z <= cfg.intensity_range[1]):
            status, reason = 'missing', 'out_of_range'
            message = f'intensity {z:g} V outside intensity_range {list(cfg.intensity_range)}'
        elif (cfg.gate > 0 and ekf is not None and tracking and last is not None
              and self.origin_ns is not None):
            d = float(ekf.innovation_distance((stamp_ns - self.origin_ns) / NS, z)[0])
            if not d <= cfg.gate:
                status, reason = 'missing', 'gated'
                message = (f'intensity {z:g} V is {d:.3g} standard deviations from the '
                           f'prediction (gate {cfg.gate:g})')
        if status == 'missing':
            st.missing[reason] += 1
            st.bad_since += 1
        mu = 0.0
        if last is not None:
            mu = (stamp_ns - last) / NS
            self.stats.record_interval(mu, self.config.dt, self.config.max_gap)
        if self.origin_ns is None:
            self.origin_ns = stamp_ns
        self.last_ns = stamp_ns
        st.last_stamp_ns = stamp_ns
        self.pointing.started(stamp_ns)
        used = None if status == 'missing' else z
        t = (stamp_ns - self.origin_ns) / NS
        try:
            # an absurd reading (1e308 V) overflows in the detectors: the checks below
            # restart the aligner, so numpy's warnings would only repeat them
            with np.errstate(over='ignore', invalid='ignore'):
                if self.supervisor is not None and reason == 'negative':
                    # missing to the tracker (NaN: None would mean z), but the dark the
                    # detectors need to see
                    turn = float(self.supervisor.step(t, z, math.nan)[0])
                else:
                    turn = float(self.aligner.step(t, used)[0])
        except (led.AlignmentError, np.linalg.LinAlgError) as exc:
            return self._fail(stamp_ns, str(exc))
        if self.supervisor is not None:
            self._note_supervisor(self.supervisor, stamp_ns)
        prior = posterior = None
        if ekf is not None and tracking:
            prior = Estimate(ekf.x_prior[0].copy(), _sym(ekf.P_prior[0]))
            posterior = Estimate(ekf.x[0].copy(), _sym(ekf.P[0]))
            # on plain floats: numpy's reductions cost more than these eight entries
            if not all(math.isfinite(v) for a in (*prior, *posterior)
                       for v in a.ravel().tolist()):
                return self._fail(stamp_ns, 'the EKF estimate is not finite')
            big = max(max(map(abs, posterior.x.tolist())),
                      math.sqrt(max(posterior.P.trace().item(), 0.0)))
            if big > cfg.state_limit:
                self.health_error = (f'EKF state or covariance {big:.3g} beyond state_limit '
                                     f'{cfg.state_limit:g}')
                self.reset('state_health')
                return self._reject('filter_error', stamp_ns,
                                    f'{self.health_error}; aligner restarted')
            st.singular += int(ekf.singular[0])
        if not math.isfinite(turn) or not math.isfinite(self.base + turn):
            return self._fail(stamp_ns, f'the command {turn} is not finite')
        applied = self._clamp(turn)
        if applied != turn:
            st.clamped += 1
            self.aligner.correct_last_turn(np.array([applied - turn]))
        self.base += applied
        if status != 'missing':
            st.used += 1
        st.commands += 1
        return AlignOutcome(status, reason, message, stamp_ns, mu, self.base, applied, prior,
                            posterior)

    def _clamp(self, turn: float) -> float:
        """Return the turn limited to max_step and to the joint limits base_limits."""
        cfg = self.config
        if cfg.max_step > 0:
            turn = min(max(turn, -cfg.max_step), cfg.max_step)
        lo, hi = cfg.base_limits
        return min(max(self.base + turn, lo), hi) - self.base

    def _note_supervisor(self, sup: Supervisor, stamp_ns: int) -> None:
        """Count the supervisor's declared loss and state change at this sample."""
        p = self.pointing
        if bool(sup.declared[0]):
            p.losses += 1
            p.last_loss_ns = stamp_ns
        new = STATES[int(sup.state[0])]
        if new != p.state:
            if new == 'tracking':
                reason = 'light back after a hold' if sup.resumed[0] else 'light found'
                if p.state == 'lost':
                    p.reacquisitions += 1
                else:
                    p.acquisitions += 1
            else:
                reason = ('search' if new != 'lost' else 'loss declared'
                          + (', held' if sup.held[0] > 0 else ''))
            p.enter(new, reason, stamp_ns)

    def reset(self, reason: str) -> None:
        """Restart the aligner from its initial state; the base stays where it is."""
        self.stats.resets[reason] += 1
        self._restart(f'restarted ({reason})')

    def reconfigure(self, config: AlignmentConfig) -> str:
        """Switch to a new (validated) config; in place if only TUNABLE fields changed."""
        old, self.config = self.config, config
        self.input.configure(_frequency(config))
        changed = {f.name for f in fields(config)
                   if getattr(config, f.name) != getattr(old, f.name)}
        if changed - set(TUNABLE):
            self.reset('reconfigured')
            return f'aligner restarted ({", ".join(sorted(changed - set(TUNABLE)))} changed)'
        if self.supervisor is not None:     # its gate, noise (sqrt R_11) and max_step
            self.supervisor.reconfigure(config.supervisor())
        a = self.tracker
        if isinstance(a, led.ScanningEKF):
            ekf = config.ekf()
            a.config, a.gain = ekf, ekf.gain
            a.Q, a.R = np.asarray(ekf.Q, dtype=float), np.asarray(ekf.R, dtype=float)
        elif isinstance(a, (led.HillClimbing, led.ThreePointAveraging)):
            a.gamma = float(config.gamma)
            if isinstance(a, led.ThreePointAveraging):
                a.clip = bool(config.clip)
        return 'new parameters in use'

    def skip(self, stamp_ns: int, now_ns: Optional[int] = None) -> None:
        """Count a sample received while the loop is paused: not used, but an input."""
        self.stats.received += 1
        self.stats.paused += 1
        if now_ns is not None:
            self.input.note(int(stamp_ns), now_ns)

    def diagnostics(self, *, consume: bool = True,
                    now_ns: Optional[int] = None) -> list[Status]:
        """
        Return the statuses of the session's diagnostic tasks (see doc/diagnostics.md).

        'aligner', 'time scale' and, with the supervisor, 'pointing'; with now_ns
        (receiver clock) first the input's 'input frequency' and 'timestamp delay'.
        consume=True resets the since-last-update counters (long gaps, bad samples, a
        self restart).
        """
        st = self.stats
        ekf = self.ekf
        out = self.input.run(now_ns) if now_ns is not None else []
        out += [aligner_status(st, self.config, self.base, self.health_error,
                               None if ekf is None else (ekf.x[0], ekf.P[0]), self.paused,
                               (MISSING_REASONS, REJECT_REASONS, RESET_REASONS)),
                time_scale(st, self.config)]
        if self.supervisor is not None:
            out.append(pointing_status(self.pointing, self.supervisor.verdict, self.paused,
                                       st.last_stamp_ns))
        if consume:
            st.gaps_over_bound = 0
            st.bad_since = 0
            self.health_error = ''
        return out

    # -- internals ------------------------------------------------------------------------

    def _reject(self, reason: str, stamp_ns: int, message: str) -> AlignOutcome:
        self.stats.rejected[reason] += 1
        self.stats.bad_since += 1
        return AlignOutcome('rejected', reason, message, stamp_ns)

    def _fail(self, stamp_ns: int, message: str) -> AlignOutcome:
        """Restart the aligner after a failed step; nothing is published for this sample."""
        self.reset('filter_error')
        return self._reject('filter_error', stamp_ns, f'{message}; aligner restarted')


def _frequency(config: AlignmentConfig) -> FrequencyParams:
    """Return the FrequencyStatus params of a config's intensity input."""
    return expected_frequency(config.expected_rate, config.rate_tolerance, config.dt)


def _sym(P: FloatArray) -> FloatArray:
    return (P + P.T) / 2
