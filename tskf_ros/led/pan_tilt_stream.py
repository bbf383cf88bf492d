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
The two-axis session as the alignment node runs it: input checks, counters, diagnostics.

two_axis.pan_tilt_session.PanTiltSession steps the two-axis aligner on stamped intensities
and turns the mount; PanTiltStream wraps it with what the node's one-axis session
(alignment_session.AlignmentSession) also does around its aligner, so that the node treats
both alike: a negative intensity or one outside intensity_range is a missing sample, every
sample is counted (AlignStats: used, missing, rejected and restarts by reason, gaps and
mu = interval / dt from the stamps), the input's frequency and stamps are watched, the
pointing state's transitions are recorded, and the diagnostic tasks are those of the
one-axis session ('aligner', 'time scale', 'pointing'), with the second joint's command
and the two pointing errors in 'aligner'.  Angles in degrees, intensities in volts.
"""

from dataclasses import dataclass, replace
import math
from typing import Optional

import numpy as np

from tskf_ros.core.diagnostic_status import expected_frequency, InputStream, Status, WARN
from tskf_ros.core.units import NS
from tskf_ros.led.alignment_config import check_range
from tskf_ros.led.alignment_diagnostics import aligner_status, pointing_status, time_scale
from tskf_ros.led.alignment_session import (AlignStats, MISSING_REASONS, REJECT_REASONS,
                                            RESET_REASONS)
from tskf_ros.led.intensity_model import FloatArray
from tskf_ros.led.pointing_stats import PointingStats, Transition
from tskf_ros.led.two_axis.pan_tilt_session import (PanTiltOutcome, PanTiltSession,
                                                    PanTiltSessionConfig)

# why a state was entered, as the one-axis session says it
ENTERED = {'tracking': 'light found', 'acquiring': 'search', 'lost': 'loss declared'}


@dataclass(frozen=True)
class PanTiltStreamConfig:
    """The two-axis session's settings and the node's checks around it."""

    session: PanTiltSessionConfig
    algorithm: str = 'ekf'                  # the node's algorithm (diagnostics)
    negative_is_missing: bool = True
    intensity_range: tuple[float, ...] = ()
    max_gap: float = 1.0                    # s: a longer gap warns in 'time scale'
    expected_rate: float = 0.0              # Hz the input frequency expects; 0: 1 / dt
    rate_tolerance: float = 0.5

    def __post_init__(self) -> None:
        """Check the node's checks (as one axis does); raise AlignmentError with the reason."""
        check_range('intensity_range', self.intensity_range, empty=True)

    @property
    def dt(self) -> float:
        """Return the nominal sample interval (s)."""
        return self.session.dt


@dataclass(frozen=True)
class PanTiltStep:
    """One sample's outcome and mu, the seconds since the previous sample (0: the first)."""

    outcome: PanTiltOutcome
    mu: float = 0.0
    # the filter's prediction into this sample (x, P), where it steered at the last sample
    # too (not at a hand-over, where the supervisor restarts it from its fit)
    prior: Optional[tuple[FloatArray, FloatArray]] = None


class PanTiltStream:
    """A PanTiltSession with the one-axis session's checks and counters; see the module doc."""

    def __init__(self, config: PanTiltStreamConfig) -> None:
        self.config = config
        self.stats = AlignStats()
        self.paused = False
        self.input = InputStream(expected_frequency(config.expected_rate,
                                                    config.rate_tolerance, config.dt))
        self.pointing = PointingStats()
        self.session = PanTiltSession(config.session)
        self.health_error = ''
        self.failures_reported = 0      # the session's smoothing failures at the last report
        self.pointing.enter(self.session.state, 'start', None)

    @property
    def joints(self) -> tuple[float, float]:
        """Return the last commanded [pan, tilt] (deg)."""
        return float(self.session.joints[0]), float(self.session.joints[1])

    @property
    def last_ns(self) -> Optional[int]:
        """Return the stamp of the last sample taken (None: none since the start)."""
        return self.session.last_ns

    @property
    def pat_state(self) -> str:
        """Return the pointing state (acquiring, tracking, lost; disabled without one)."""
        return self.pointing.state

    def add(self, stamp_ns: int, z: float, *, now_ns: Optional[int] = None) -> PanTiltStep:
        """Take one sample (stamp in ns, intensity in V; receiver clock now); say what it did."""
        st, cfg = self.stats, self.config
        st.received += 1
        if now_ns is not None:
            self.input.note(int(stamp_ns), now_ns)
        z = float(z)
        reason, message = '', ''
        if z < 0 and cfg.negative_is_missing:
            reason, message = 'negative', f'intensity {z:g} V < 0'
        elif math.isfinite(z) and abs(z) > cfg.session.state_limit:
            reason = 'out_of_range'
            message = f'intensity {z:g} V is beyond state_limit {cfg.session.state_limit:g} V'
        elif math.isfinite(z) and cfg.intensity_range and not (
                cfg.intensity_range[0] <= z <= cfg.intensity_range[1]):
            reason = 'out_of_range'
            message = f'intensity {z:g} V outside intensity_range {list(cfg.intensity_range)}'
        last = self.session.last_ns
        steered = self.session.steering
        out = self.session.add(stamp_ns, None if reason else z)
        if reason and out.status in ('used', 'missing'):
            out = replace(out, status='missing', reason=reason, message=message)
        mu = 0.0
        if out.status == 'rejected':
            st.rejected[out.reason] += 1
            st.bad_since += 1
            if out.reason == 'filter_error':
                st.resets['filter_error'] += 1
                self.health_error = out.message
        else:
            if out.status == 'reset':
                st.resets[out.reason] += 1
            elif last is not None:
                mu = (int(stamp_ns) - last) / NS
                self.stats.record_interval(mu, self.config.dt, self.config.max_gap)
            if out.status == 'missing':
                st.missing[out.reason] += 1
                st.bad_since += 1
            else:
                st.used += 1
            st.last_stamp_ns = int(stamp_ns)
            self.pointing.started(int(stamp_ns))
        if out.command is not None:
            st.commands += 1
        self._note_state(st.last_stamp_ns or None)
        prior = None
        if out.estimate is not None and (steered or last is None):
            tracker = self.session.tracker
            x, P = getattr(tracker, 'x_prior')[0], getattr(tracker, 'P_prior')[0]
            prior = (np.array(x, dtype=float), (P + P.T) / 2)
        return PanTiltStep(out, mu, prior)

    def _note_state(self, stamp_ns: Optional[int]) -> None:
        """Record the supervisor's state change at this sample, counted as in one axis."""
        p, state = self.pointing, self.session.state
        if state == p.state:
            return
        sup = self.session.aligner
        if state == 'tracking':
            if p.state == 'lost':
                p.reacquisitions += 1
            else:
                p.acquisitions += 1
            resumed = getattr(sup, 'resumed', None)
            reason = ('light back after a hold' if resumed is not None and bool(resumed[0])
                      else ENTERED[state])
        elif state == 'lost':
            p.losses += 1
            p.last_loss_ns = stamp_ns
            held = getattr(sup, 'held', None)
            reason = ENTERED[state] + (', held' if held is not None and held[0] > 0 else '')
        else:
            reason = ENTERED.get(state, 'start')
        p.enter(state, reason, stamp_ns)

    def skip(self, stamp_ns: int, now_ns: Optional[int] = None) -> None:
        """Count a sample received while the loop is paused: not used, but an input."""
        self.stats.received += 1
        self.stats.paused += 1
        if now_ns is not None:
            self.input.note(int(stamp_ns), now_ns)

    def reset(self, reason: str) -> None:
        """Restart the aligner from its prior; the mount stays where it is."""
        self.stats.resets[reason] += 1
        self.session.reset()
        self.pointing.enter(self.session.state, f'restarted ({reason})',
                            self.stats.last_stamp_ns or None)

    def acquire(self) -> bool:
        """Force a new cold search (~/acquire); False without a supervisor."""
        if not self.session.acquire():
            return False
        self.pointing.requests += 1
        self.pointing.enter('acquiring', 'acquire requested', self.stats.last_stamp_ns or None)
        return True

    def take_transitions(self) -> list[Transition]:
        """Return the state transitions since the last call, oldest first, and forget them."""
        return self.pointing.take()

    def reconfigure(self, config: PanTiltStreamConfig) -> str:
        """Switch to a new (validated) config: the aligner restarts where the mount is."""
        self.input.configure(expected_frequency(config.expected_rate, config.rate_tolerance,
                                                config.dt))
        joints = self.joints
        lo, hi = config.session.tilt_limits
        session = replace(config.session, joints0=(joints[0], min(max(joints[1], lo), hi)))
        # the failures so far stay counted (and warned of) as before
        self.session = PanTiltSession(session,
                                      earlier_failures=self.session.smoothing_failures)
        self.config = config
        self.stats.resets['reconfigured'] += 1
        self.pointing.enter(self.session.state, 'restarted (reconfigured)',
                            self.stats.last_stamp_ns or None)
        return 'two-axis aligner restarted with the new parameters'

    def diagnostics(self, *, consume: bool = True,
                    now_ns: Optional[int] = None) -> list[Status]:
        """Return the one-axis session's tasks, with the two joints and the two errors."""
        st = self.stats
        out = self.input.run(now_ns) if now_ns is not None else []
        pan, tilt = self.joints
        stat = aligner_status(st, self.config, pan, self.health_error, None, self.paused,
                              (MISSING_REASONS, REJECT_REASONS, RESET_REASONS))
        stat.add('Tilt command (deg)', tilt)
        estimate = self.session.estimate()
        if estimate is not None:
            stat.add('x1 estimate (V)', estimate.intensity)
            stat.add('d_c estimate (deg)', estimate.error[0])
            stat.add('d_e estimate (deg)', estimate.error[1])
            stat.add('Covariance trace', float(np.trace(estimate.P)))
        failures = self.session.smoothing_failures
        stat.add('Smoothing failures', failures)
        if failures > self.failures_reported:
            stat.merge_summary(WARN, f'{failures - self.failures_reported} smoothing(s) of '
                               "the filter's window failed since the last update: its "
                               'estimate was kept')
        out += [stat, time_scale(st, self.config)]
        if self.pointing.state != 'disabled':
            out.append(pointing_status(self.pointing, getattr(self.session.aligner, 'verdict',
                                                              None),
                                       self.paused, st.last_stamp_ns))
        if consume:
            st.gaps_over_bound = 0
            st.bad_since = 0
            self.failures_reported = failures
            self.health_error = ''
        return out
