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
Cost per sample of the Section III interval checks on a stream with long random gaps.

    python bench/bench_interval_checks.py

The estimator checks every new sampling interval (in nominal periods) for Fang & de
Callafon's Definitions 2-3.  Before, a new interval re-ran `pathological_intervals` and
`degenerate_intervals`, which enumerate 2..max(T); now `IntervalChecker` tests the new
interval alone.  Both are measured here side by side, in one run, on the same model and
gaps (period 1 ms, gaps 1 ms .. 50 s), and the session's whole add() cost is printed.
Figures only; nothing is asserted.
"""

import os
import time

import numpy as np

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from tskf_ros.core import irregular  # noqa: E402
from tskf_ros.core.units import NS  # noqa: E402
from tskf_ros.owc.session import (EstimatorConfig, EstimatorSession,  # noqa: E402
                                  model_from_flat)

PERIOD = 0.001
MODEL = model_from_flat(A=[0.0, -1.0, 1.0, 0.0], C=[1.0, 0.0], Q=[1e-3, 0, 0, 1e-3],
                        R=[1.0], x0=[0.0, 0.0], P0=[1.0, 0.0, 0.0, 1.0], name='rotation')


def main() -> None:
    rng = np.random.default_rng(0)
    gaps = rng.integers(1, 50_000, size=200)
    session = EstimatorSession(EstimatorConfig(MODEL, period=PERIOD, max_jump=100.0,
                                               gate=0.0, nonpositive_is_gap=False,
                                               history_window=0.0, max_backward=0.0))
    A_h, _, _ = session.kf.transition_matrices(PERIOD)
    t = 1_700_000_000 * NS
    session.add(t, 0.1)
    start = time.perf_counter()
    for g in gaps:
        t += int(g) * 1_000_000
        session.add(t, 0.1)
    per_sample = (time.perf_counter() - start) / gaps.size
    check = irregular.IntervalChecker(A_h, MODEL.C)
    start = time.perf_counter()
    for g in gaps:
        check.warning(int(g))
    new = (time.perf_counter() - start) / gaps.size
    sample = gaps[:5]
    start = time.perf_counter()
    for g in sample:                         # what a new interval cost before
        irregular.pathological_intervals(A_h, int(g))
        irregular.degenerate_intervals(A_h, MODEL.C, int(g))
    old = (time.perf_counter() - start) / sample.size
    print(f'{gaps.size} samples, gaps 1..50 000 periods of {PERIOD * 1e3:g} ms')
    print(f'session.add, whole:                         {per_sample * 1e6:10.1f} us/sample')
    print(f'one new interval, IntervalChecker.warning:  {new * 1e6:10.1f} us')
    print(f'one new interval, enumerating 2..kappa:     {old * 1e6:10.1f} us '
          f'(mean of {sample.size}, kappa ~ {int(sample.mean())})')
    print(f'ratio: {old / new:,.0f}x')


if __name__ == '__main__':
    main()
