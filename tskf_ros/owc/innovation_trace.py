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
Run the estimator session over a recorded stream and keep what an analysis needs.

`run_stream(config, events)` feeds measurements and inputs, in the order given, to the
same EstimatorSession the timescale_estimator node runs (so mu comes from the stamps as
the node computes it, with the node's transition, gap handling and rejections), and
collects from its Outcomes:

- the trace of filter steps, segment by segment (a segment starts at a (re)start from
  x0, P0): the mu, y and input u of every step the session made, after late samples were
  inserted; `tskf_ros.core.noise_fit` re-runs this trace with other Q and R;
- the innovation of every measurement step as the session computed it:
  e_k = y_k - C xhat_k - D against the predictor at t_k, S_k = C P_k C^T + R_d with
  R_d = R / mu_k (or the sample's own variance under use_message_variance), the last
  revision of a stamp superseding earlier ones;
- the final corrected and predicted estimate at every stamp, and the session's counters.

No ROS, no I/O.
"""

from bisect import bisect_right
from dataclasses import dataclass, field, replace
from typing import Callable, Iterable, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.noise_fit import (fit, FitError, FitResult, negative_log_likelihood,
                                     StepRecord, with_noise)
from tskf_ros.core.noise_search import FitProgress
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, Outcome, Stats
from tskf_ros.owc.stream_events import Event, EventColumns, Input, Measurement
from tskf_ros.owc.trace_columns import EstimateColumns, InnovationColumns, TraceColumns

__all__ = ['EstimateColumns', 'Event', 'EventColumns', 'fit_stream', 'Input',
           'InnovationColumns', 'Measurement', 'run_stream', 'StreamFit', 'StreamRun',
           'StreamRunner', 'TraceColumns']

FloatArray = NDArray[np.float64]
# a point of a segment: (segment, stamp ns)
Key = tuple[int, int]

# statuses of a measurement or input that the session took as (part of) a point
TAKEN = ('accepted', 'inserted', 'reset')
# points made final at a time
FINAL_AT_ONCE = 4096


@dataclass
class StreamRun:
    """What a session did over a stream (see the module docstring)."""

    segments: TraceColumns                  # (temporary files: close() frees them)
    innovations: InnovationColumns
    estimates: Optional[EstimateColumns]    # x(t|t) and xhat(t) (if asked for)
    stats: Stats
    measurements: int
    inputs: int
    gated_stamps: set[int]                  # stamps the innovation gate rejected
    steps: int                              # filter steps (those of segments, if kept)


class _Collector:
    """
    Follow the session's outcomes; keep the final revision of everything per stamp.

    The newest points (those a late sample may still revise) are kept by (segment,
    stamp); older ones go, final, into columns (trace_columns).
    """

    def __init__(self, config: EstimatorConfig, *, trace: bool = True,
                 estimates: bool = False) -> None:
        self.config = config
        m = config.model
        self.C = m.C
        self.D = np.zeros(m.C.shape[0]) if m.D is None else np.asarray(m.D, dtype=float)
        self.R = m.R
        p = m.C.shape[0]
        self.segment = 0
        self.y: dict[Key, tuple[FloatArray, float]] = {}    # y and its variance
        self.jumps: dict[Key, int] = {}                     # sigma_ns
        self.pred: dict[Key, tuple[FloatArray, FloatArray]] = {}    # (x, P)
        self.corr: dict[Key, FloatArray] = {}               # x
        self.terms: dict[Key, tuple[FloatArray, FloatArray]] = {}   # (e, S)
        # seg -> [(stamp, u)] accepted, in order; the input in force when it started
        self.inputs: dict[int, list[tuple[int, FloatArray]]] = {0: []}
        self.input_stamps: dict[int, list[int]] = {0: []}
        self.carry: dict[int, Optional[FloatArray]] = {0: None}
        self.last_u: Optional[FloatArray] = None
        # the final points
        self.live = 4 * config.history_size + FINAL_AT_ONCE
        self.final: Optional[Key] = None
        self.steps = 0
        self.trace = TraceColumns() if trace else None
        self.innovations = InnovationColumns(p)
        self.estimates = EstimateColumns() if estimates else None

    def new_segment(self) -> None:
        self.segment += 1
        self.inputs.setdefault(self.segment, [])
        self.input_stamps.setdefault(self.segment, [])
        self.carry[self.segment] = self.last_u

    def u_at(self, seg: int, stamp_ns: int) -> Optional[FloatArray]:
        i = bisect_right(self.input_stamps[seg], stamp_ns)
        return self.inputs[seg][i - 1][1] if i else self.carry[seg]

    def _check(self, key: Key) -> None:
        """Refuse a revision of a point already final (older than the session's history)."""
        if self.final is not None and key <= self.final:
            raise RuntimeError(f'the innovation trace was sent a point at {key[1]} ns, at or '
                               f'before one it had made final ({self.final[1]} ns)')

    def outcome(self, out: Outcome, *, y: Optional[FloatArray] = None, variance: float = 0.0,
                stamp_ns: int = 0) -> None:
        if out.status == 'reset':
            self.new_segment()
        seg = self.segment
        if y is not None and out.status in TAKEN:
            self._check((seg, stamp_ns))
            self.y[(seg, stamp_ns)] = (y, variance)
        jumps = {j.stamp_ns: j for j in out.jumps}
        for j in out.jumps:
            self._check((seg, j.stamp_ns))
            self.jumps[(seg, j.stamp_ns)] = j.sigma_ns
        for est in out.estimates:
            key = (seg, est.stamp_ns)
            self._check(key)
            if est.kind == 'predicted':
                self.pred[key] = (est.x, est.P)
                continue
            self.corr[key] = est.x
            jump, prior, meas = jumps.get(est.stamp_ns), self.pred.get(key), self.y.get(key)
            if jump is None or prior is None or meas is None:
                continue
            x, P = prior
            yk, var = meas
            mu = jump.mu
            Rd = (np.eye(self.C.shape[0]) * var if self.config.use_message_variance and var > 0
                  else self.R / mu)
            e = yk - self.C @ x - self.D
            self.terms[key] = (e, self.C @ P @ self.C.T + Rd)
        if len(self.jumps) >= self.live + FINAL_AT_ONCE:
            self._freeze(sorted(self.jumps)[FINAL_AT_ONCE - 1])

    def input_outcome(self, out: Outcome, stamp_ns: int, u: FloatArray) -> None:
        if out.status in TAKEN:
            # the input is in force from its stamp: in the new segment after a reset
            seg = self.segment + (out.status == 'reset')
            self.inputs.setdefault(seg, []).append((stamp_ns, u))
            self.input_stamps.setdefault(seg, []).append(stamp_ns)
            self.last_u = u
        self.outcome(out)       # an input point steps the filter from the previous point

    def _freeze(self, last: Key) -> None:
        """Make every point at or before `last` final: into the columns, out of the dicts."""
        for seg, t in sorted(k for k in self.jumps if k <= last):
            sigma = self.jumps.pop((seg, t))
            self.steps += 1
            meas = self.y.get((seg, t))
            if self.trace is not None:
                # a point with a measurement that was later stepped from; input-only: y None
                self.trace.append(seg, StepRecord(
                    mu=(sigma - t) / NS, y=None if meas is None else meas[0],
                    u=self.u_at(seg, t),
                    variance=(meas[1] if meas is not None
                              and self.config.use_message_variance else 0.0)))
        final = [self.terms.pop(key) for key in sorted(k for k in self.terms if k <= last)]
        if final:
            self.innovations.extend(np.array([e for e, _ in final]),
                                    np.array([S for _, S in final]))
        points = sorted({k for k in self.corr if k <= last}
                        | {k for k in self.pred if k <= last})
        for key in points:
            x_c, x_p = self.corr.pop(key, None), self.pred.pop(key, None)
            if self.estimates is not None:
                self.estimates.append(key[0], key[1], x_c, None if x_p is None else x_p[0])
        for key in [k for k in self.y if k <= last]:
            del self.y[key]
        # the inputs a later point may still be in: those after `last`, and the one before
        for seg in [s for s in self.inputs if s < last[0]]:
            del self.inputs[seg], self.input_stamps[seg], self.carry[seg]
        stamps = self.input_stamps.get(last[0], [])
        drop = bisect_right(stamps, last[1]) - 1
        if drop > 0:
            del stamps[:drop], self.inputs[last[0]][:drop]
        self.final = last

    def finish(self) -> None:
        """Make every point final."""
        keys = list(self.jumps) + list(self.terms) + list(self.corr) + list(self.pred)
        if keys:
            self._freeze(max(keys))


class StreamRunner:
    """
    A session fed one event at a time (`append`), as read; `result()` is the StreamRun.

    Passed to `bag_analysis.read_stream` as its events, the bag is run as it is read and
    no event is kept.  The arguments are run_stream's.
    """

    def __init__(self, config: EstimatorConfig, *, use_now: bool = False,
                 observe: Optional[Callable[[Outcome], None]] = None,
                 trace: bool = True, estimates: bool = False) -> None:
        self.config, self.use_now, self.observe = config, use_now, observe
        self.session = EstimatorSession(config)
        self.col = _Collector(config, trace=trace, estimates=estimates)
        self.measurements, self.inputs = 0, 0
        self.gated: set[int] = set()

    def append(self, ev: Event) -> None:
        """Feed one event to the session."""
        session, col, observe = self.session, self.col, self.observe
        if isinstance(ev, Input):
            self.inputs += 1
            u = np.asarray(ev.u, dtype=float).reshape(-1)
            out = session.add_input(ev.stamp_ns, u)
            if observe is not None:
                observe(out)
            col.input_outcome(out, int(ev.stamp_ns), u)
            return
        self.measurements += 1
        out = session.add(ev.stamp_ns, ev.value, ev.variance,
                          now_ns=ev.log_ns if self.use_now else None)
        if observe is not None:
            observe(out)
        if out.status == 'rejected' and out.reason == 'gated':
            self.gated.add(int(ev.stamp_ns))
        y = np.atleast_1d(np.asarray(ev.value, dtype=float)).reshape(-1)
        col.outcome(out, y=y, variance=float(ev.variance), stamp_ns=int(ev.stamp_ns))

    def result(self) -> StreamRun:
        """Make every point final; return what the session did."""
        col = self.col
        col.finish()
        return StreamRun(col.trace if col.trace is not None else TraceColumns(),
                         col.innovations, col.estimates,
                         self.session.stats, self.measurements, self.inputs, self.gated,
                         col.steps)


def run_stream(config: EstimatorConfig, events: Iterable[Event], *,
               use_now: bool = False,
               observe: Optional[Callable[[Outcome], None]] = None,
               trace: bool = True, estimates: bool = False) -> StreamRun:
    """
    Feed Measurement and Input events to a fresh EstimatorSession; return a StreamRun.

    use_now passes each measurement's log_ns as the receiver clock (now_ns), as the
    offline replay does (it matters only for max_future and the input-rate statistics).
    observe, if given, is called with every outcome, in order (e.g. a smoother's).
    trace: keep the filter steps (StreamRun.segments; else empty); estimates: keep the
    final estimates (StreamRun.estimates; else None).
    """
    runner = StreamRunner(config, use_now=use_now, observe=observe, trace=trace,
                          estimates=estimates)
    for ev in events:
        runner.append(ev)
    return runner.result()


# the fewest measurement steps per fitted parameter
MIN_STEPS_PER_PARAMETER = 10
# rounds of (fit, then the node's gate at the fit) before the gated set must be stable
GATE_ROUNDS = 4


@dataclass
class StreamFit:
    """A fit of Q and R to a stream, and the session run with the fitted parameters."""

    result: FitResult
    config: EstimatorConfig         # the input config with the fitted Q and R
    run: StreamRun                  # the session with the fitted config (node's gate on)
    excluded: set[int]              # stamps left out of the likelihood: the gate's at the fit
    rounds: int
    gate_stable: bool
    notes: list[str] = field(default_factory=list)
    # log L of the input config's own Q and R over the last round's steps (the
    # likelihood's, gate off): the steps of `excluded` only if gate_stable
    file_log_likelihood: float = float('nan')


def without(events: Iterable[Event], stamps: set[int]) -> Iterable[Event]:
    """Return the events (again iterable) leaving out the measurements stamped in `stamps`."""
    if isinstance(events, EventColumns):
        return events.events(without=stamps)
    return [ev for ev in events
            if not (isinstance(ev, Measurement) and int(ev.stamp_ns) in stamps)]


def fit_stream(config: EstimatorConfig, events: Iterable[Event], *,
               fit_Q: bool = True, fit_R: bool = True,
               progress: Optional[FitProgress] = None) -> StreamFit:
    """
    Fit Q and R by maximum likelihood over the innovations of the session's steps.

    The innovation gate is the one rejection that depends on Q and R: with it on, the
    optimiser could shrink the likelihood by rejecting samples.  So the likelihood is
    maximised with the gate off over the samples that the node's gate keeps at the fitted
    Q and R (at first: at the config's Q and R), and the fit is repeated until that set no
    longer changes (at most GATE_ROUNDS).  Every other rejection, the transition, gap
    handling and resets are the session's.  use_message_variance is turned off (with it R
    would not be used).
    Raises FitError with the reason (too few samples, no convergence).  progress: see
    noise_fit.fit.  events: iterated once per run of the session (an EventColumns, or a
    list).
    """
    notes = []
    if config.use_message_variance:
        notes.append('use_message_variance was on: turned off, so that the fitted R is used')
        config = replace(config, use_message_variance=False)
    base = replace(config, gate=0.0)
    # start from what the node's gate rejects at the file's own Q and R (an absurd reading
    # would make the likelihood infinite with the gate off)
    excluded: set = set(run_stream(config, events, trace=False).gated_stamps)
    for rounds in range(1, GATE_ROUNDS + 1):
        trace = run_stream(base, without(events, excluded))
        k = ((config.model.Q.shape[0] if fit_Q else 0)
             + (config.model.C.shape[0] if fit_R else 0))
        n = trace.innovations.count
        if n < MIN_STEPS_PER_PARAMETER * max(k, 1):
            raise FitError(f'too few samples: {n} measurement steps for {k} parameters '
                           f'(at least {MIN_STEPS_PER_PARAMETER * max(k, 1)} needed)')
        result = fit(base.model, base.transition, trace.segments, fit_Q=fit_Q, fit_R=fit_R,
                     progress=progress)
        file_ll = -negative_log_likelihood(base.model, base.transition, trace.segments)
        del trace           # the next round's is made before this one would be let go
        fitted = replace(config, model=with_noise(config.model, result.Q, result.R))
        run = run_stream(fitted, events, trace=False)
        stable = run.gated_stamps == excluded
        if stable:
            break
        excluded = set(run.gated_stamps)
    else:
        notes.append(f'the gated set still changed after {GATE_ROUNDS} rounds')
    return StreamFit(result, fitted, run, excluded, rounds, stable, notes, file_ll)
