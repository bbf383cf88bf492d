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
Fixed-lag smoothing of an EstimatorSession's stream: x(t_{k-L}|t_k) from its outcomes.

The session's steps t_k -> t_{k+1} (x(t_k|t_k), P(t_k|t_k) or, at an input-only point,
the prediction into it; x(t_{k+1}|t_k), P(t_{k+1}|t_k); mu_k), read from its Outcomes as
bag/replay/rts_replay reads them, feed `tskf_ros.core.fixed_lag.FixedLagSmoother`: the
RTS backward equations (Rauch, Tung & Striebel 1965; Sarkka 2013, Theorem 8.2) over the
window of the L + 1 newest stepped points, with F_k = I + mu_k A or e^{A mu_k}.
"""

from collections import deque
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.fixed_lag import FixedLagSmoother, Lagged
from tskf_ros.core.timescale_kalman import StepResult
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, Outcome

__all__ = ['LaggedEstimate', 'LaggedEstimates']

Array = NDArray[np.float64]


class LaggedEstimate(NamedTuple):
    """A smoothed estimate: x(t|t + delay), P(t|t + delay) at stamp t, and its step's mu."""

    stamp_ns: int
    mu: float           # s: the step from this point to the next
    delay: float        # s: t_newest - t, the newest point whose step is in the window
    x: Array
    P: Array


class _Step(NamedTuple):
    """One step t -> sigma of the forward run, as the smoother takes it."""

    stamp_ns: int
    sigma_ns: int
    x_f: Array
    P_f: Array
    x_p: Array
    P_p: Array


class LaggedEstimates:
    """
    The fixed-lag smoothed estimates of a session, fed its outcomes one at a time.

    `outcome(out)` returns the points that became L steps old, each x(t_{k-L}|t_k).  A
    late sample (the session re-runs its history from the left neighbour) revises the
    steps kept: the window is rebuilt from the L + 1 newest steps as revised, and a point
    it has not output yet comes out smoothed on the revised run; the stamps output only
    increase (a point already output is not output again; a late point older than the
    newest output gets none).  A reset ends the run: the window's points not yet output come out
    smoothed on what it holds (a shorter delay), and the next run starts an empty window.
    Memory and time per step are O(L) (the window, one backward pass).
    """

    def __init__(self, lag: int, config: EstimatorConfig) -> None:
        self.lag = int(lag)
        self.kf = config.model.make_filter(config.transition)
        self._restart()

    def _restart(self) -> None:
        self.steps: deque[_Step] = deque(maxlen=self.lag + 1)
        self.smoother = FixedLagSmoother(self.lag)
        self.added = 0                          # steps added to this smoother
        self.last_ns: Optional[int] = None      # the newest point output
        self.prior: dict[int, tuple[Array, Array]] = {}   # the newest prediction

    def outcome(self, out: Outcome) -> list[LaggedEstimate]:
        """Take what the session made of a sample or an input; return what became due."""
        done: list[LaggedEstimate] = []
        if out.status == 'reset':
            done = self.flush()
            self._restart()
        if out.status not in ('accepted', 'inserted', 'reset'):
            return done
        steps = self._steps(out)
        if out.status == 'inserted' and steps:
            first = steps[0].stamp_ns
            kept = [s for s in self.steps if s.stamp_ns < first] + steps
            return done + self._rebuild(kept[-(self.lag + 1):])
        for step in steps:
            got = self._add(step)
            # a full window's oldest point is the one L steps back
            if got is not None and self._new(self.steps[0]):
                done.append(self._estimate(got, 0))
        return done

    def reconfigure(self, config: EstimatorConfig) -> list[LaggedEstimate]:
        """
        Take a new model (a run-time parameter change): return the window's points, flushed.

        The next window starts empty on the new model; the stamps output still only
        increase (a late sample re-run across the change outputs nothing already out).
        """
        done = self.flush()
        last = self.last_ns
        self.kf = config.model.make_filter(config.transition)
        self._restart()
        self.last_ns = last
        return done

    def flush(self) -> list[LaggedEstimate]:
        """Return the window's points not yet output, smoothed on what it holds."""
        first = self.added - len(self.steps)        # the number of the window's oldest
        rows = [(got, got.point - first) for got in self.smoother.flush()]
        return [self._estimate(got, row) for got, row in rows if self._new(self.steps[row])]

    def _add(self, step: _Step) -> Optional[Lagged]:
        self.steps.append(step)
        self.added += 1
        return self.smoother.add(self._result(step), self._F(step))

    def _rebuild(self, steps: list[_Step]) -> list[LaggedEstimate]:
        """Start the window anew with `steps` (a revised run); return its due point."""
        self.steps = deque(maxlen=self.lag + 1)
        self.smoother = FixedLagSmoother(self.lag)
        self.added = 0
        got = None
        for step in steps:
            got = self._add(step)
        if got is None or not self._new(self.steps[0]):
            return []
        return [self._estimate(got, 0)]

    def _new(self, step: _Step) -> bool:
        return self.last_ns is None or step.stamp_ns > self.last_ns

    def _estimate(self, got: Lagged, row: int) -> LaggedEstimate:
        step = self.steps[row]
        if self.last_ns is None or step.stamp_ns > self.last_ns:
            self.last_ns = step.stamp_ns
        return LaggedEstimate(step.stamp_ns, (step.sigma_ns - step.stamp_ns) / NS, got.delay,
                              got.x, got.P)

    def _steps(self, out: Outcome) -> list[_Step]:
        """Return the steps of an outcome, oldest first (the revised ones of a re-run)."""
        corrected: dict[int, tuple[Array, Array]] = {}
        predicted: dict[int, tuple[Array, Array]] = {}
        for e in out.estimates:
            (predicted if e.kind == 'predicted' else corrected)[e.stamp_ns] = (e.x, e.P)
        steps = []
        for j in out.jumps:
            # an input-only point has no corrected estimate: its prediction stands for it
            at = corrected.get(j.stamp_ns) or predicted.get(j.stamp_ns) or \
                self.prior.get(j.stamp_ns) or self._predicted_into(j.stamp_ns)
            into = predicted.get(j.sigma_ns)
            if at is None or into is None:
                continue
            steps.append(_Step(j.stamp_ns, j.sigma_ns, at[0], at[1], into[0], into[1]))
        if predicted:       # the newest prediction: its point may be an input-only one
            newest = max(predicted)
            self.prior = {newest: predicted[newest]}
        return steps

    def _predicted_into(self, stamp_ns: int) -> Optional[tuple[Array, Array]]:
        for s in self.steps:
            if s.sigma_ns == stamp_ns:
                return s.x_p, s.P_p
        return None

    def _F(self, step: _Step) -> Array:
        return self.kf.transition_matrices((step.sigma_ns - step.stamp_ns) / NS)[0]

    @staticmethod
    def _result(step: _Step) -> StepResult:
        mu = (step.sigma_ns - step.stamp_ns) / NS
        n = step.x_f.shape[0]
        return StepResult(mu, step.x_f, step.P_f, step.x_p, step.P_p, np.zeros(0),
                          np.zeros((0, n)))
