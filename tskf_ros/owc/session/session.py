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
A streaming estimator session: stamped samples in, time-scale filter estimates out.

Every valid sample is a point t_k of the time scale, mu(t_k) = t_{k+1} - t_k (Cai et al.
Section IV-C; Bohner & Wintz Definition 2.3), so sample k+1 triggers

    step(mu(t_k), y(t_k)):  x(t_k | t_k)  and  xhat(t_{k+1})

of the TimeScaleKalmanFilter (Bohner & Wintz Table 3, Cai Table I), with R_d = R / mu or
the sample's own variance.  An input u is held from its stamp (zero-order hold), which is
a point without a measurement.  See doc/design/estimator_session.md.
"""

from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from tskf_ros.core.diagnostic_status import (expected_frequency, FrequencyParams,
                                             InputStream, Status)
from tskf_ros.core.timescale_kalman import FilterError, NonRegressiveError
from tskf_ros.core.units import NS
from tskf_ros.owc.session.admission import Admission, Gate, stamp_rejection
from tskf_ros.owc.session.config import EstimatorConfig
from tskf_ros.owc.session.diagnostics import filter_health, SessionState, time_scale
from tskf_ros.owc.session.health import checked, finite, StateLimitError
from tskf_ros.owc.session.history import History, Point
from tskf_ros.owc.session.outcome import Estimate, FloatArray, Jump, Outcome, Reading, Stats
from tskf_ros.owc.session.runs import Runs
from tskf_ros.owc.session.sampling_intervals import Intervals


# restarts after which the interval since the last measurement point is still an interval
GAP_RESETS = ('forward_jump', 'gate_lockout')


def _frequency(config: EstimatorConfig) -> FrequencyParams:
    """Return the FrequencyStatus params of a config's measurement input."""
    return expected_frequency(config.expected_rate, config.rate_tolerance, config.period)


def reading(value: ArrayLike) -> Reading:
    """Return a measurement as a float (one entry) or a flat float array."""
    y = np.atleast_1d(np.asarray(value, dtype=float)).reshape(-1)
    return y.item() if y.size == 1 else y


class EstimatorSession(Runs):
    """The filter fed from a stream of stamped samples; see the module docstring."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.stats = Stats()
        self.kf = config.model.make_filter(config.transition)
        self.u: FloatArray = np.zeros(self.kf.B.shape[1])  # the input in force (held)
        self.u_stamp_ns = 0                         # its stamp (0: none yet)
        self.health_error = ''                      # why the filter re-initialised itself
        self.gated_in_a_row = 0
        self._variance = 0.0                        # of the sample being added
        self.history = History(config.history_size, config.history_window * NS)
        self.intervals = Intervals(self.stats, config)
        self.input = InputStream(_frequency(config))
        self._use(config)

    def _use(self, config: EstimatorConfig) -> None:
        """Derive what the checks need from a config (and the filter of its model)."""
        self.config = config
        self.admission = Admission(config, self.kf.p)
        self.gate = Gate(config, self.kf)
        self.history.resize(config.history_size, config.history_window * NS)
        self.intervals.configure(config)
        self.input.configure(_frequency(config))
        self._max_jump_ns = config.max_jump * NS
        self._state_limit = config.state_limit
        self._use_variance = config.use_message_variance
        self._uses_input = config.model.B is not None     # no B: u is 0

    @property
    def points(self) -> Sequence[Point]:
        """Return the points kept for rewinding, oldest first."""
        return self.history.points

    # -- public API -----------------------------------------------------------------------

    def add(self, stamp_ns: int, power: ArrayLike, variance: float = 0.0, *,
            now_ns: Optional[int] = None) -> Outcome:
        """Take one sample (stamp in ns, measurement, its variance); say what it did."""
        self.stats.received += 1
        if type(stamp_ns) is not int:
            stamp_ns = int(stamp_ns)
        if now_ns is not None:
            self.input.note(stamp_ns, now_ns)
        y = power if type(power) is float else reading(power)
        refused = self.admission.check(stamp_ns, y, variance, now_ns)
        if refused is not None:
            if refused.status == 'gap':     # Cai et al. IV-C: an interruption, not a point
                self.stats.rejected[refused.reason] += 1
                return Outcome('gap', refused.reason, refused.message)
            return self._reject(refused.reason, refused.message)
        self._variance = float(variance) if self._use_variance else 0.0
        points = self.history.points
        if points:
            dt = stamp_ns - points[-1].stamp_ns
            if 0 < dt <= self._max_jump_ns:
                return self._append(stamp_ns, y)
            return self._place(stamp_ns, y, dt)
        return self._start(stamp_ns, y)

    def add_input(self, stamp_ns: int, u: ArrayLike) -> Outcome:
        """
        Take one input sample u (B's columns), held from its stamp to the next input.

        The stamp becomes a point without a measurement (or merges into the newest
        point); an input older than the newest point is rejected ('input_late').
        """
        st, cfg = self.stats, self.config
        st.inputs_received += 1
        stamp_ns = int(stamp_ns)
        u = np.asarray(u, dtype=float).reshape(-1)
        if not self._uses_input:
            return self._reject('no_input_matrix', 'the model has no B: input ignored')
        refused = stamp_rejection(stamp_ns, input_sample=True)
        if refused is not None:
            return self._reject(refused.reason, refused.message)
        if u.size != self.u.size:
            return self._reject('input_size', f'input has {u.size} entries, B has '
                                f'{self.u.size} columns')
        if not finite(u):
            return self._reject('input_non_finite', f'input {u} is not finite')
        points = self.history.points
        if not points:
            return self._hold(stamp_ns, u, 'accepted', 'held',
                              'input held until the first measurement')
        last = points[-1]
        dt = stamp_ns - last.stamp_ns
        if dt > self._max_jump_ns:
            self.reset('forward_jump')
            return self._hold(stamp_ns, u, 'reset', 'forward_jump',
                              f'input stamp jumped {dt / NS:.3f} s forward (> max_jump); '
                              're-initialised, input held')
        if -dt > cfg.max_backward * NS:
            self.reset('backward_jump')
            return self._hold(stamp_ns, u, 'reset', 'backward_jump',
                              f'input stamp jumped {-dt / NS:.3f} s backward (> max_backward);'
                              ' re-initialised, input held')
        if dt < 0:
            return self._reject('input_late', f'input stamp {stamp_ns / NS:.9f} s is '
                                f'{-dt / NS:.3f} s older than the newest point')
        if dt == 0:
            if last.has_input:
                return self._reject('input_duplicate', f'input stamp {stamp_ns / NS:.9f} s '
                                    'repeats the last input')
            last.u, last.has_input = u, True
            return self._hold(stamp_ns, u, 'accepted', 'merged',
                              'input merged into the newest point')
        out = self._append(stamp_ns, None, u)
        if out.status == 'accepted':
            self._hold(stamp_ns, u, 'accepted')
        return out

    def reset(self, reason: str, message: str = '') -> Outcome:
        """
        Forget the history; the next sample starts a new time scale from x0, P0.

        The input in force is kept: it is the plant's, not the filter's.
        """
        self.stats.resets[reason] += 1
        self.kf = self.config.model.make_filter(self.config.transition)
        self.history.points.clear()
        return Outcome('reset', reason, message or f'filter re-initialised ({reason})')

    def reconfigure(self, config: EstimatorConfig) -> Outcome:
        """Switch to a new (already validated) config, keeping the estimate if n is unchanged."""
        old, old_model = self.kf, self.config.model
        self.kf = config.model.make_filter(config.transition)
        self._use(config)
        if self.kf.B.shape[1] != self.u.size:
            self.u, self.u_stamp_ns = np.zeros(self.kf.B.shape[1]), 0
            return self.reset('reconfigured', f'input dimension changed -> {self.u.size}')
        if self.kf.n != old.n:
            return self.reset('reconfigured', f'state dimension changed {old.n} -> '
                              f'{self.kf.n}')
        if not (np.array_equal(config.model.x0, old_model.x0)
                and np.array_equal(config.model.P0, old_model.P0)):
            return self.reset('set_state', 'x0 / P0 changed: the estimate starts again from '
                              'them at the next sample')
        self.kf.x, self.kf.P = old.x, old.P
        self.intervals.recheck()        # the same intervals may mean something else now
        return Outcome('accepted', 'reconfigured', 'new parameters in use')

    def pending(self) -> Optional[int]:
        """Stamp of the last point, whose corrected estimate waits for the next point."""
        points = self.history.points
        return points[-1].stamp_ns if points else None

    def diagnostics(self, *, consume: bool = True,
                    now_ns: Optional[int] = None) -> list[Status]:
        """
        Return the statuses of the session's diagnostic tasks (see doc/diagnostics.md).

        'filter health' and 'time scale'; with now_ns (the receiver clock) first the
        input's 'input frequency' and 'timestamp delay' (diagnostic_updater's
        FrequencyStatus and TimeStampStatus, which start a new update).  consume=True
        resets the since-last-update counters (gaps over the bound, rejects, a self
        re-initialisation).
        """
        st = self.stats
        out = self.input.run(now_ns) if now_ns is not None else []
        out += [filter_health(st, SessionState(len(self.history.points), self.u, self.kf.P,
                                               self.health_error)),
                time_scale(st, self.config, self.kf.P)]
        if consume:
            st.gaps_over_bound = 0
            st.rejected_since = 0
            self.health_error = ''
        return out

    # -- internals ------------------------------------------------------------------------

    def _place(self, stamp_ns: int, y: Reading, dt: int) -> Outcome:
        """Take a sample that is not just after the newest point: merge, restart or insert."""
        cfg, points = self.config, self.history.points
        if dt == 0 and points[-1].y is None:
            return self._merge_measurement(stamp_ns, y)
        if dt == 0:
            return self._reject('duplicate', f'stamp {stamp_ns / NS:.9f} s repeats the last')
        if dt > 0:
            return self._restart('forward_jump', stamp_ns, y,
                                 f'stamp jumped {dt / NS:.3f} s forward (> max_jump)')
        if -dt > cfg.max_backward * NS:
            return self._restart('backward_jump', stamp_ns, y,
                                 f'stamp jumped {-dt / NS:.3f} s backward (> max_backward)')
        first = points[0]
        if -dt > cfg.history_window * NS or stamp_ns < first.stamp_ns:
            # every point but the first is within history_window of the newest (trim)
            if stamp_ns == first.stamp_ns and first.y is not None:
                return self._reject('duplicate', f'stamp {stamp_ns / NS:.9f} s is already a '
                                    'point')
            return self._reject('too_old', f'stamp {stamp_ns / NS:.9f} s is {-dt / NS:.3f} s '
                                'late, older than the history')
        i = self.history.index(stamp_ns)
        if i < len(points) and points[i].stamp_ns == stamp_ns and points[i].y is not None:
            return self._reject('duplicate', f'stamp {stamp_ns / NS:.9f} s is already a point')
        return self._insert(stamp_ns, y, i)

    def _reject(self, reason: str, message: str) -> Outcome:
        self.stats.rejected[reason] += 1
        self.stats.rejected_since += 1
        return Outcome('rejected', reason, message)

    def _start(self, stamp_ns: int, y: Reading) -> Outcome:
        x, P = self.kf.x.copy(), self.kf.P.copy()
        self.history.points.append(Point(stamp_ns, y, x, P, self.u,
                                         has_input=self.u_stamp_ns == stamp_ns,
                                         variance=self._variance))
        self.stats.last_measurement_ns = stamp_ns
        self._accepted(stamp_ns, P)
        return Outcome('accepted', estimates=[Estimate('predicted', stamp_ns, x, P)])

    def _hold(self, stamp_ns: int, u: FloatArray, status: str, reason: str = '',
              message: str = '') -> Outcome:
        """Make u the input in force from stamp_ns on and count it."""
        self.u, self.u_stamp_ns = u, stamp_ns
        self.stats.inputs_accepted += 1
        return Outcome(status, reason, message)

    def _merge_measurement(self, stamp_ns: int, y: Reading) -> Outcome:
        """Give the newest point, an input-only one, its measurement (not stepped yet)."""
        last = self.history.points[-1]
        last.y, last.variance = y, self._variance
        self.intervals.measured(stamp_ns)
        self._accepted(stamp_ns, last.P)
        return Outcome('accepted', 'merged', 'measurement merged into an input point')

    def _restart(self, reason: str, stamp_ns: int, y: Reading, message: str) -> Outcome:
        last = self.stats.last_measurement_ns
        if reason in GAP_RESETS and 0 < last < stamp_ns:
            # the time scale had no measurement point from last to here: a gap J
            self.intervals.record(last, stamp_ns)
        self.reset(reason)
        out = self._start(stamp_ns, y)
        out.status, out.reason, out.message = 'reset', reason, message + '; re-initialised'
        return out

    def _unhealthy_restart(self, stamp_ns: int, y: Reading, why: str) -> Outcome:
        """Re-initialise after an absurd or failed step and start again from this sample."""
        self.health_error = why
        return self._restart('state_health', stamp_ns, y, why)

    def _accepted(self, stamp_ns: int, P: FloatArray, trace: Optional[float] = None) -> None:
        st = self.stats
        st.accepted += 1
        st.last_stamp_ns = max(st.last_stamp_ns, stamp_ns)
        st.covariance_trace = float(np.trace(P)) if trace is None else trace

    def _step(self, point: Point, sigma_ns: int, revised: bool, out: Outcome) -> float:
        """
        step(mu, y) from point to sigma; add its estimates and mu to out; return trace P.

        Raises FilterError on a step that is not sound (the filter may have moved).
        """
        mu = (sigma_ns - point.stamp_ns) / NS
        y = point.y
        u = point.u if self._uses_input else None
        if point.variance > 0 and y is not None:
            # the sample's own variance is its R_d = R / mu (Table 3's noise on the point);
            # a product that underflows is the smallest normal variance instead
            res = self.kf.step(mu, y, u, R=max(point.variance * mu, 1e-300))
        else:
            res = self.kf.step(mu, y, u)
        trace = checked(res, self._state_limit)
        predicted = Estimate('predicted', sigma_ns, res.x_predicted, res.P_predicted, revised)
        if y is None:       # an input-only point has no corrected estimate
            out.estimates.append(predicted)
        else:
            out.estimates += (Estimate('corrected', point.stamp_ns, res.x_corrected,
                                       res.P_corrected, revised), predicted)
        out.jumps.append(Jump(point.stamp_ns, sigma_ns, revised))
        return trace

    def _append(self, stamp_ns: int, y: Optional[Reading],
                u: Optional[FloatArray] = None) -> Outcome:
        """Step the newest point to a new one: a measurement (y) or an input (u)."""
        kf, points = self.kf, self.history.points
        saved = kf.x, kf.P          # a step replaces them, never writes into them
        out = Outcome('accepted', '', '', [], [])
        try:
            trace = self._step(points[-1], stamp_ns, False, out)
        except FilterError as exc:
            kf.x, kf.P = saved      # the step may have moved it before the check
            why = (f'the step gave {exc}' if isinstance(exc, StateLimitError)
                   else f'step refused: {exc}')
            if y is None or isinstance(exc, NonRegressiveError):
                # this mu only: the state is sound and the next sample's mu will differ
                return self._reject('filter_error', f'step refused: {exc}')
            return self._unhealthy_restart(stamp_ns, y, why)
        x, P = kf.x, kf.P
        st = self.stats
        if u is not None:               # an input-only point
            points.append(Point(stamp_ns, None, x, P, u, True))
        elif y is not None:
            gated = self.gate.why(y, x, P, self._variance)
            if gated:
                kf.x, kf.P = saved
                return self._gated(stamp_ns, y, gated)
            self.gated_in_a_row = 0
            points.append(Point(stamp_ns, y, x, P, self.u, False, self._variance))
            self.intervals.measured(stamp_ns)
            st.accepted += 1
        mu = out.jumps[0].mu
        st.mu_current = mu
        if mu > st.mu_max:
            st.mu_max = mu
        if stamp_ns > st.last_stamp_ns:
            st.last_stamp_ns = stamp_ns
        st.covariance_trace = trace
        self.history.trim()
        return out

    def _gated(self, stamp_ns: int, y: Reading, why: str) -> Outcome:
        """Reject a sample that failed the gate, or restart from it after gate_patience."""
        patience = self.config.gate_patience
        if self.gated_in_a_row >= patience:
            self.gated_in_a_row = 0
            return self._restart('gate_lockout', stamp_ns, y,
                                 f'{why}; {patience + 1} samples in a row failed the gate')
        self.gated_in_a_row += 1
        return self._reject('gated', why)

    def _insert(self, stamp_ns: int, y: Reading, i: int) -> Outcome:
        """Insert a late measurement before points[i] and re-run the filter from t_j."""
        history, kf, st = self.history, self.kf, self.stats
        rewind = history.rewind(stamp_ns, y, self._variance, i)
        saved = kf.x, kf.P
        out = Outcome('inserted', 'late')
        try:
            history.rerun(rewind, kf, self._step, out)
        except FilterError as exc:
            history.put_back(rewind)
            kf.x, kf.P = saved
            return self._reject('filter_error', f're-run after a late sample refused: {exc}')
        new = rewind.rerun[rewind.new]
        gated = self.gate.why(y, new.x, new.P, self._variance) if rewind.has_prior else ''
        if gated:
            history.put_back(rewind)
            kf.x, kf.P = saved
            return self._reject('gated', gated)
        # the interval between the measurement points around it is now two intervals
        before, after = history.measured_around(rewind)
        history.commit(rewind)
        if after is not None:
            self.intervals.forget(after)
            self.intervals.record(stamp_ns, after)
        if before is not None:
            self.intervals.record(before, stamp_ns)
        st.last_measurement_ns = max(st.last_measurement_ns, stamp_ns)
        st.inserted += 1
        st.mu_current = out.jumps[-1].mu
        st.mu_max = max(st.mu_max, max(jump.mu for jump in out.jumps))
        self._accepted(stamp_ns, kf.P)
        history.trim()
        out.message = (f'late sample {stamp_ns / NS:.9f} s inserted; {len(out.estimates)} '
                       'estimates revised')
        return out
