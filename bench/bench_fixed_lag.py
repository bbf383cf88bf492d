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
Cost per sample of the fixed-lag smoother (tskf_ros.core.FixedLagSmoother) at L = 10, 100, 1000.

    OPENBLAS_NUM_THREADS=1 python bench/bench_fixed_lag.py [--repeats 7] [--samples 200]

Thread CPU time (time.thread_time_ns) per sample, min / median over the repeats, for:
the filter's `step` alone (Euler, a measurement every point, irregular mu); that step's
jump F (`transition_matrices`, cached by mu); and `FixedLagSmoother.add` with a full
window (the step results made beforehand, so the add is timed alone).  The model is a
position-velocity pair (n = 2) and a 6-state chain (n = 6), one output.

Then the estimator node's path with smoothing_lag = L: `EstimatorSession.add` alone
against `EstimatorSession.add` + `LaggedEstimates.outcome` (the outcome read into the
window, its add and the backward pass), per sample on a 100 Hz stream of the n = 2 model,
measured side by side in one run.  Figures only; nothing is asserted.
"""

import argparse
import os
import platform
import statistics
import time
from typing import Callable

import numpy as np

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from tskf_ros.core import FixedLagSmoother, TimeScaleKalmanFilter  # noqa: E402
from tskf_ros.core.units import NS  # noqa: E402
from tskf_ros.owc.lagged_estimates import LaggedEstimates  # noqa: E402
from tskf_ros.owc.session import (EstimatorConfig, EstimatorSession,  # noqa: E402
                                  model_from_flat)

LAGS = (10, 100, 1000)
SIZES = (2, 6)
MUS = (0.01, 0.012, 0.008, 0.011)       # a few graininesses, as a jittery 100 Hz stream


def model(n: int) -> dict:
    """Return a chain of integrators with damping: x_i' = x_{i+1} - 0.1 x_i, y = x_0."""
    A = np.diag(np.ones(n - 1), 1) - 0.1 * np.eye(n)
    C = np.zeros((1, n))
    C[0, 0] = 1.0
    return {'A': A, 'C': C, 'Q': 0.5 * np.eye(n), 'R': 0.01, 'x0': np.zeros(n),
            'P0': np.eye(n)}


def per_sample(run: Callable[[int], None], count: int, repeats: int) -> tuple[float, float]:
    """Return (min, median) thread CPU microseconds per sample of run(count) over repeats."""
    times = []
    for _ in range(repeats):
        start = time.thread_time_ns()
        run(count)
        times.append((time.thread_time_ns() - start) / count / 1e3)
    return min(times), statistics.median(times)


def bench(n: int, lag: int, samples: int, repeats: int) -> dict:
    """Time step, transition_matrices and add for one model size and lag."""
    rng = np.random.default_rng(0)
    kf = TimeScaleKalmanFilter(**model(n))
    total = lag + 1 + samples * repeats
    mus = [MUS[k % len(MUS)] for k in range(total)]
    ys = rng.normal(size=(total, 1))
    results = [kf.step(mu, y) for mu, y in zip(mus, ys)]
    Fs = [kf.transition_matrices(mu)[0] for mu in mus]
    smoother = FixedLagSmoother(lag)
    for k in range(lag + 1):
        smoother.add(results[k], Fs[k])
    cursor = [lag + 1]

    def add(count: int) -> None:
        k = cursor[0]
        for i in range(k, k + count):
            smoother.add(results[i], Fs[i])
        cursor[0] = k + count

    timed = TimeScaleKalmanFilter(**model(n))

    def step(count: int) -> None:
        for i in range(count):
            timed.step(mus[i], ys[i])

    def jump(count: int) -> None:
        for i in range(count):
            timed.transition_matrices(mus[i])

    return {'step': per_sample(step, samples, repeats), 'F': per_sample(jump, samples, repeats),
            'add': per_sample(add, samples, repeats)}


def session_config(n: int) -> EstimatorConfig:
    """Return the session config of model(n), sampled at about 100 Hz."""
    m = model(n)
    flat = {key: np.ravel(value).tolist() for key, value in m.items()}
    flat['R'] = [m['R']]
    return EstimatorConfig(model_from_flat(name='chain', state_names=tuple(
        f'x{i}' for i in range(n)), D=[], G=[], B=[], **flat), period=0.01,
        history_size=max(1000, 4 * max(LAGS)), min_rate_fraction=0.0, stale_timeout=0.0,
        gate=0.0, nonpositive_is_gap=False)


def bench_node(n: int, lag: int, samples: int, repeats: int) -> dict:
    """Time session.add with and without LaggedEstimates.outcome, per sample."""
    rng = np.random.default_rng(1)
    total = lag + 2 + samples * repeats
    stamps = np.cumsum([int(MUS[k % len(MUS)] * NS) for k in range(total)]) + NS
    ys = rng.normal(size=total).tolist()
    config = session_config(n)

    def make(smooth: bool) -> Callable[[int], None]:
        session = EstimatorSession(config)
        lagged = LaggedEstimates(lag, config) if smooth else None
        cursor = [0]

        def feed(count: int) -> None:
            k = cursor[0]
            for i in range(k, k + count):
                out = session.add(int(stamps[i]), ys[i])
                if lagged is not None:
                    lagged.outcome(out)
            cursor[0] = k + count
        feed(lag + 2)       # a full window before the timing
        return feed
    plain, smoothed = make(False), make(True)
    return {'add': per_sample(plain, samples, repeats),
            'lagged': per_sample(smoothed, samples, repeats)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--repeats', type=int, default=7)
    parser.add_argument('--samples', type=int, default=200)
    args = parser.parse_args()
    print(f'{platform.python_implementation()} {platform.python_version()}, '
          f'numpy {np.__version__}, {platform.machine()}; thread CPU time per sample, '
          f'us (min / median of {args.repeats} x {args.samples} samples)')
    print(f'{"n":>3} {"L":>5} {"filter step":>15} {"F (cached)":>15} '
          f'{"fixed-lag add":>17} {"add / step":>11}')
    for n in SIZES:
        for lag in LAGS:
            r = bench(n, lag, max(10, args.samples * 10 // lag), args.repeats)
            (s, sm), (f, fm), (a, am) = r['step'], r['F'], r['add']
            print(f'{n:>3} {lag:>5} {s:7.1f} / {sm:5.1f} {f:7.2f} / {fm:5.2f} '
                  f'{a:8.1f} / {am:6.1f} {a / s:11.1f}')
    print('\nthe estimator node with smoothing_lag = L (n = 2): per sample, us (min / median)')
    print(f'{"L":>5} {"session.add":>15} {"add + lagged":>17} {"ratio":>7}')
    for lag in LAGS:
        r = bench_node(2, lag, max(10, args.samples * 10 // lag), args.repeats)
        (p, pm), (q, qm) = r['add'], r['lagged']
        print(f'{lag:>5} {p:7.1f} / {pm:5.1f} {q:8.1f} / {qm:6.1f} {q / p:7.1f}')


if __name__ == '__main__':
    main()
