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
Samples taken in runs: admitted one by one, then stepped through the filter in one call.

For samples t_1 < t_2 < ... that pass the admission checks, each within max_jump of the
one before, the session's steps are step(mu_k, y(t_{k-1})) with mu_k = t_k - t_{k-1}
(Bohner & Wintz Table 3), each kept if y(t_k) passes the gate at the prediction
xhat(t_k), P(t_k): TimeScaleKalmanFilter.run with the gate as its innovation test.
"""

from typing import Optional, Union

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.diagnostic_status import InputStream
from tskf_ros.core.timescale_kalman import (FilterError, InnovationTest, StepResult,
                                            TimeScaleKalmanFilter)
from tskf_ros.core.units import NS
from tskf_ros.owc.session.admission import Admission, Gate
from tskf_ros.owc.session.health import checked
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
        out: list[Union[Run, Outcome]] = []
        i = 0
        while i < len(stamps):
            j = self._admitted(stamps, ys, vs, nows, i)
            if j > i:
                run = self._run(stamps_ns[i:j], values[i:j], nows[i:j])
                if run.count:
                    out.append(run)
                i += run.count
                if i == j:
                    continue        # all kept: sample j is looked at again
            out.append(self.add(stamps[i], ys[i], vs[i], now_ns=nows[i]))
            i += 1
        return out

    def _admitted(self, stamps: list[int], ys: list[float], vs: list[float],
                  nows: list[int], i: int) -> int:
        """Return j: samples i .. j-1 can be a run (see add_many)."""
        points = self.history.points
        if self.kf.p != 1 or self._use_variance or not points:
            return i
        last = points[-1]
        if last.y is None or last.variance != 0.0 or last.u is not self.u:
            return i
        stamp, max_jump, check = last.stamp_ns, self._max_jump_ns, self.admission.check
        j = i
        for t, y, v, now in zip(stamps[i:], ys[i:], vs[i:], nows[i:]):
            if not 0 < t - stamp <= max_jump or check(t, y, v, now) is not None:
                break
            stamp = t
            j += 1
        return j

    def _run(self, stamps: NDArray[np.int64], values: NDArray[np.float64],
             nows: list[int]) -> Run:
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
        count, trace = res.steps, st.covariance_trace
        for k, (t, y) in enumerate(zip(stamps[:count].tolist(), values.tolist())):
            try:
                trace = checked(StepResult(mu[k], res.x_corrected[k], res.P_corrected[k],
                                           x_p[k], P_p[k], z, z), self._state_limit)
            except FilterError:     # add() takes this sample again and decides
                count = k
                kf.x, kf.P = (x_p[k - 1], P_p[k - 1]) if k else saved
                break
            points.append(Point(t, y, x_p[k], P_p[k], self.u, False, 0.0))
            self.intervals.measured(t)
        if count:
            for t, now in zip(stamps[:count].tolist(), nows[:count]):
                self.input.note(t, now)
            st.received += count
            st.accepted += count
            self.gated_in_a_row = 0
            st.mu_current = mu[count - 1].item()
            st.mu_max = max(st.mu_max, mu[:count].max().item())
            st.last_stamp_ns = max(st.last_stamp_ns, int(stamps[count - 1]))
            st.covariance_trace = trace
            self.history.trim()
        return Run(count, stamps[:count], previous[:count], res.x_corrected[:count],
                   res.P_corrected[:count], x_p[:count], P_p[:count])
