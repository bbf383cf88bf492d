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
Samples taken in runs: admitted, stepped through the filter and checked, each in one call.

For samples t_1 < t_2 < ... that pass the admission checks, each within max_jump of the
one before, the session's steps are step(mu_k, y(t_{k-1})) with mu_k = t_k - t_{k-1}
(Bohner & Wintz Table 3), each kept if y(t_k) passes the gate at the prediction
xhat(t_k), P(t_k): TimeScaleKalmanFilter.run with the gate as its innovation test.  The
admission checks (Admission.passes), the health checks of the steps (health.sound_steps),
the intervals and the input's diagnostics take the run's arrays at once.
"""

from typing import Optional, Union

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.diagnostic_status import InputStream
from tskf_ros.core.timescale_kalman import InnovationTest, TimeScaleKalmanFilter
from tskf_ros.core.units import NS
from tskf_ros.owc.session.admission import Admission, Gate
from tskf_ros.owc.session.health import sound_steps
from tskf_ros.owc.session.history import History, Point
from tskf_ros.owc.session.outcome import FloatArray, Outcome, Run, Stats
from tskf_ros.owc.session.sampling_intervals import Intervals


class Runs:
    """The session's intake of samples in runs (a part of EstimatorSession)."""

    kf: TimeScaleKalmanFilter
    history: History
    admission: Admission
    gate: Gate
    stats: Stats
    intervals: Intervals
    input: InputStream   # noqa: A003 - the session's own name for it
    u: FloatArray
    gated_in_a_row: int
    _use_variance: bool
    _uses_input: bool
    _max_jump_ns: float
    _state_limit: float

    def add(self, stamp_ns: int, power: float, variance: float = 0.0, *,
            now_ns: Optional[int] = None) -> Outcome:
        """Take one sample (EstimatorSession.add)."""
        raise NotImplementedError

    def add_many(self, stamps_ns: NDArray[np.int64], values: NDArray[np.float64],
                 variances: NDArray[np.float64], now_ns: NDArray[np.int64]
                 ) -> list[Union[Run, Outcome]]:
        """
        Take samples in order as add() one at a time does; return what each did, in order.

        A stretch of samples of a one-output model that pass the admission checks and
        follow each other within max_jump is run through the filter in one call
        (TimeScaleKalmanFilter.run, the gate as its innovation test): a Run for those
        accepted; every other sample (and one a run stops at) goes through add(): its
        Outcome.  The filter, history and counters end as add() would leave them.
        """
        stamps, ys = stamps_ns.tolist(), values.tolist()
        vs, nows = variances.tolist(), now_ns.tolist()
        # the samples that can follow the one before in a run: admitted (Admission.check,
        # at once for all) and within max_jump of it; `breaks` are the others, sorted
        admitted = np.zeros(len(stamps), dtype=bool)
        if len(stamps) and self.kf.p == 1:
            admitted = self.admission.passes(stamps_ns, values, variances, now_ns)
        step = np.diff(stamps_ns)
        follows = admitted.copy()
        follows[1:] &= (0 < step) & (step <= self._max_jump_ns)
        breaks = np.flatnonzero(~follows)
        out: list[Union[Run, Outcome]] = []
        i = 0
        while i < len(stamps):
            j = self._admitted(stamps, admitted, breaks, i)
            if j > i:
                run = self._run(stamps_ns[i:j], values[i:j], now_ns[i:j])
                if run.count:
                    out.append(run)
                i += run.count
                if i == j:
                    continue        # all kept: sample j is looked at again
            out.append(self.add(stamps[i], ys[i], vs[i], now_ns=nows[i]))
            i += 1
        return out

    def _admitted(self, stamps: list[int], admitted: NDArray[np.bool_],
                  breaks: NDArray[np.intp], i: int) -> int:
        """Return j: samples i .. j-1 can be a run (see add_many)."""
        points = self.history.points
        if self.kf.p != 1 or self._use_variance or not points:
            return i
        last = points[-1]
        if last.y is None or last.variance != 0.0 or last.u is not self.u:
            return i
        # sample i follows the last point, the next ones each the one before
        if not (admitted[i] and 0 < stamps[i] - last.stamp_ns <= self._max_jump_ns):
            return i
        k = int(np.searchsorted(breaks, i + 1))
        return int(breaks[k]) if k < len(breaks) else len(stamps)

    def _run(self, stamps: NDArray[np.int64], values: NDArray[np.float64],
             nows: NDArray[np.int64]) -> Run:
        """Run admitted samples in order through the filter; keep those accepted."""
        kf, points, st = self.kf, self.history.points, self.stats
        last = points[-1]
        previous = np.empty_like(stamps)
        previous[0], previous[1:] = last.stamp_ns, stamps[:-1]
        mu = (stamps - previous) / NS
        z = np.empty(stamps.size)
        z[0], z[1:] = last.y, values[:-1]
        gate = self.gate
        test = (InnovationTest(values.reshape(-1, 1), gate.R_period, gate.gate * gate.gate)
                if gate.on else None)
        saved = kf.x, kf.P
        res = kf.run(mu, z, self.u if self._uses_input else None, test=test)
        x_p, P_p = res.x_predicted, res.P_predicted
        # the health checks of every step at once; add() takes an unsound one again
        count, traces = sound_steps(res.P_corrected[:res.steps], x_p[:res.steps],
                                    P_p[:res.steps], self._state_limit)
        if count < res.steps:
            kf.x, kf.P = (x_p[count - 1], P_p[count - 1]) if count else saved
        if count:
            # the points kept (the deque keeps only its newest maxlen of them)
            first = max(0, count - (points.maxlen or count))
            u = self.u
            points.extend(Point(t, y, x_p[k], P_p[k], u, False, 0.0) for k, t, y in zip(
                range(first, count), stamps[first:count].tolist(),
                values[first:count].tolist()))
            self.intervals.measured_many(stamps[:count])
            self.input.note_many(stamps[:count].tolist(), nows[:count].tolist())
            st.received += count
            st.accepted += count
            self.gated_in_a_row = 0
            st.mu_current = mu[count - 1].item()
            st.mu_max = max(st.mu_max, mu[:count].max().item())
            st.last_stamp_ns = max(st.last_stamp_ns, int(stamps[count - 1]))
            st.covariance_trace = traces[count - 1].item()
            self.history.trim()
        return Run(count, stamps[:count], previous[:count], res.x_corrected[:count],
                   res.P_corrected[:count], x_p[:count], P_p[:count])
