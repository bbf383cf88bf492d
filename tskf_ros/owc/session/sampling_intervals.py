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
The gaps and sampling intervals of the measurement points, and Fang & de Callafon's checks.

An interval J between measurement points is a gap when J > jump_factor * period; in
nominal periods it is kappa = round(J / period).  Fang & de Callafon view the stream as
the discrete system of one nominal period, A_h = the filter's transition over `period`,
measured after kappa periods: each new kappa gets the Section III checks (pathological,
Definition 2; degenerate, Definition 3; irregular.IntervalChecker), and for a scalar model
Theorem 2's bounds of the peak covariance for kappa in [min, max] seen, eq. (25), with
the measurement variance R / period at every sample.
"""

from typing import Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import irregular
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.core.units import NS
from tskf_ros.owc.session.config import EstimatorConfig
from tskf_ros.owc.session.outcome import IntervalWarning, PeakBounds, Stats


class Intervals:
    """Keep the gap and interval statistics of one session's Stats."""

    GAP_MEMORY = 1000       # gaps remembered individually for diagnostics

    def __init__(self, stats: Stats, config: EstimatorConfig) -> None:
        self.stats = stats
        self.configure(config)

    def configure(self, config: EstimatorConfig) -> None:
        """Use a new config; the checks are made again from it when next needed."""
        self.config = config
        self.period, self.jump_s = config.period, config.jump_factor * config.period
        self._filter: Optional[TimeScaleKalmanFilter] = None
        self._checker: Optional[irregular.IntervalChecker] = None
        self._quiet_ns = 0      # an interval between measurements known to record nothing

    def measured(self, stamp_ns: int) -> None:
        """Record the interval from the previous measurement point (gaps, kappa)."""
        st = self.stats
        last = st.last_measurement_ns
        if stamp_ns - last == self._quiet_ns:      # as before: nothing new to record
            st.last_measurement_ns = stamp_ns
            return
        if 0 < last < stamp_ns:
            self.record(last, stamp_ns)
            J = (stamp_ns - last) / NS
            if self.kappa(J) in st.intervals and not J > self.jump_s:
                self._quiet_ns = stamp_ns - last
        st.last_measurement_ns = max(last, stamp_ns)

    def measured_many(self, stamps_ns: NDArray[np.int64]) -> None:
        """
        Record the intervals of measurement points in order, as measured() one at a time.

        An interval of a kappa already seen and no gap records nothing: only the others
        go through measured(), in order.
        """
        st = self.stats
        if not stamps_ns.size:
            return
        previous = np.empty_like(stamps_ns)
        previous[0], previous[1:] = st.last_measurement_ns, stamps_ns[:-1]
        J = (stamps_ns - previous) / NS
        kappa = np.rint(J / self.period)
        plain = (0 < previous) & (previous < stamps_ns) & ~(J > self.jump_s)
        start = 0
        while start < stamps_ns.size:
            seen = len(st.intervals)
            known = plain[start:] & np.isin(kappa[start:], list(st.intervals))
            for k in (start + np.flatnonzero(~known)).tolist():
                st.last_measurement_ns = max(st.last_measurement_ns, int(previous[k]))
                self.measured(int(stamps_ns[k]))
                start = k + 1
                if len(st.intervals) != seen:      # a new kappa: known again from here
                    break
            else:
                break
        st.last_measurement_ns = max(st.last_measurement_ns, int(stamps_ns.max()))

    def record(self, start_ns: int, end_ns: int) -> None:
        """Record the interval between two measurement points: a gap beyond jump_factor."""
        st, cfg = self.stats, self.config
        J = (end_ns - start_ns) / NS
        self._interval(J)
        if J > self.jump_s:
            st.gaps[end_ns] = J
            st.gaps_total += 1
            if J > cfg.max_gap:
                st.gaps_over_bound += 1
            while len(st.gaps) > self.GAP_MEMORY:
                st.gaps.pop(next(iter(st.gaps)))

    def forget(self, end_ns: int) -> None:
        """Forget the gap that ended at end_ns (a late sample split it)."""
        if self.stats.gaps.pop(end_ns, None) is not None:
            self.stats.gaps_total -= 1

    def kappa(self, dt: float) -> int:
        """Return an interval of dt seconds in whole nominal periods."""
        return int(round(dt / self.period))

    def _interval(self, dt: float) -> None:
        """Keep the set of sampling intervals in nominal periods and check each new one."""
        st = self.stats
        kappa = self.kappa(dt)
        if kappa < 1 or kappa in st.intervals:
            return
        st.intervals.add(kappa)
        if len(st.intervals) == 1:          # the first: (A1) is reported with it
            self.recheck()
            return
        why = self._interval_checker().warning(kappa)
        if why is not None:
            st.interval_warnings = sorted(st.interval_warnings + [IntervalWarning(kappa, why)])
        self._peak_bounds()

    def _one_period(self) -> TimeScaleKalmanFilter:
        """Return a filter of this config, for its transition over one period."""
        if self._filter is None:
            self._filter = self.config.model.make_filter(self.config.transition)
        return self._filter

    def _interval_checker(self) -> irregular.IntervalChecker:
        """Return the Section III checks of this config's one-period transition (built once)."""
        if self._checker is None:
            kf = self._one_period()
            A_h, _, _ = kf.transition_matrices(self.period)
            self._checker = irregular.IntervalChecker(A_h, kf.C)
        return self._checker

    def recheck(self) -> None:
        """Re-run the interval checks and the scalar bounds for all intervals seen so far."""
        st = self.stats
        st.interval_warnings, st.peak_bounds = [], None
        if not st.intervals:
            return
        check = self._interval_checker()
        st.interval_warnings = [] if check.detectable else [
            IntervalWarning(1, irregular.UNDETECTABLE)]
        for k in sorted(st.intervals):
            why = check.warning(k)
            if why is not None:
                st.interval_warnings.append(IntervalWarning(k, why))
        self._peak_bounds()

    def _peak_bounds(self) -> None:
        """Theorem 2 for kappa in [min, max] seen (scalar models only)."""
        st, kf = self.stats, self._one_period()
        if kf.n == 1 and kf.p == 1 and st.intervals:
            A_h, Q_h, _ = kf.transition_matrices(self.period)
            st.peak_bounds = PeakBounds(*irregular.scalar_peak_bounds(
                float(A_h[0, 0]), float(kf.C[0, 0]), float(Q_h[0, 0]),
                float(kf.R[0, 0]) / self.period, min(st.intervals), max(st.intervals)))
