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
Benchmark: the cost of one two-axis sample in the alignment node's session, per filter.

    python bench/bench_pan_tilt.py [--samples 2000] [--repeats 5] [--noise 1.0]

Each case is a PanTiltSession (what the alignment node calls once per sample with
axes: 2) in closed loop with a one-run PanTiltLink, as pan_tilt_closed_loop runs it;
only session.add is timed, by the thread's CPU time (time.thread_time_ns).  The cases:

- default: the supervised conical-scan EKF (pat.enabled, pan_tilt.filter first_order)
  with the scan closed in the mount's joints (ConicalEKFConfig.closed_scan, the default);
- open_scan: the same with the scan of before (closed_scan False: no closed_scan_turn);
- fixed_radius: the same with the fixed 4 deg circle (dim_radius 0: no per-run radius);
- wide_sigma: the same with the Gauss-Hermite regression while a pointing prior is wider
  than 2.5 deg (ConicalEKFConfig.wide, off by default);
- no_smoother: the same without the smoother (smooth_after 0; with it, the 100th sample
  runs the smoother's passes over the first 100 samples, the `worst` column, and every
  50th after it over the last 50);
- smooth_once: the same with the first 100 samples smoothed only (smooth_every 0);
- consistent: pan_tilt.filter consistent (Gauss-Hermite, one pass);
- no_supervisor: the conical-scan EKF alone (pat.enabled false).

Each runs on exact stamps and on stamps jittered by +-`--jitter` of dt (the filter's mu
then changes at every sample).  The cases alternate (default, open_scan, ..., default,
...) for `--repeats` rounds; min and median of the us per sample are printed, with the
ratio to the default case of the same stamps in the same run, and the first sample's
cost (the session just built: what a node's first callback pays; the process's very
first sample, which also loads what the kernels need, is printed on its own).  The
kernels run as the node's console script runs them ($TSKF_JIT, else 'background',
node_runner.run_node's default), and the first line says which form ran.  A node is not
involved: the messages, DDS and the executor add their own (bench_estimator.py measures
those for the estimator).
"""

import argparse
from dataclasses import dataclass, replace
import os
import statistics
import time

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from tskf_ros.core import jit  # noqa: E402
from tskf_ros.core.units import NS  # noqa: E402
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig, CONSISTENT  # noqa: E402
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig  # noqa: E402
from tskf_ros.led.two_axis.pan_tilt_session import (PanTiltSession,  # noqa: E402
                                                    PanTiltSessionConfig)

T0 = 1_000_000_000


@dataclass(frozen=True)
class Case:
    """One session configuration to time."""

    name: str
    session: PanTiltSessionConfig


@dataclass
class Timing:
    """us per sample over the timed samples, the first sample's us and the dearest one's."""

    per_sample: float
    first: float
    worst: float                     # the dearest sample after the first, us


def cases(noise: float) -> list[Case]:
    """Return the configurations compared, the node's default first."""
    base = PanTiltSessionConfig(method='conical_ekf_pat', noise=noise)
    return [Case('default', base),
            Case('open_scan', replace(base, ekf=replace(ConicalEKFConfig(),
                                                        closed_scan=False))),
            Case('fixed_radius', replace(base, ekf=replace(ConicalEKFConfig(),
                                                           dim_radius=0.0))),
            Case('wide_sigma', replace(base, ekf=replace(ConicalEKFConfig(), wide=2.5))),
            Case('no_smoother', replace(base, ekf=replace(ConicalEKFConfig(),
                                                          smooth_after=0))),
            Case('smooth_once', replace(base, ekf=replace(ConicalEKFConfig(),
                                                          smooth_every=0))),
            Case('consistent', replace(base, ekf=CONSISTENT)),
            Case('no_supervisor', replace(base, method='conical_ekf'))]


def run(case: Case, link: PanTiltLinkConfig, samples: int, seed: int) -> Timing:
    """Run one closed loop of `samples`; return the CPU time of session.add per sample."""
    session = PanTiltSession(case.session)
    plant = PanTiltLink(link, runs=1, seed=seed)
    spent, first, worst = 0, 0, 0
    for k in range(samples):
        s = plant.sample()
        if bool(s.missing[0]):
            continue
        stamp = T0 + int(round(s.t * NS))
        z = float(s.reading[0])
        start = time.thread_time_ns()
        out = session.add(stamp, z)
        took = time.thread_time_ns() - start
        if k == 0:
            first = took
        else:
            spent += took
            worst = max(worst, took)
        if out.command is not None:
            plant.command(out.command)
    return Timing(spent / max(samples - 1, 1) / 1e3, first / 1e3, worst / 1e3)


def main() -> None:
    """Time every case on exact and jittered stamps; print the table."""
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--samples', type=int, default=2000, help='samples per loop (2000)')
    p.add_argument('--repeats', type=int, default=5, help='rounds of every case (5)')
    p.add_argument('--noise', type=float, default=1.0, help='link noise, V (1.0)')
    p.add_argument('--jitter', type=float, default=0.4,
                   help='stamp jitter as a fraction of dt, < 0.5 (0.4)')
    args = p.parse_args()
    jit.set_mode(os.environ.get(jit.MODE_VARIABLE) or 'background')
    all_cases = cases(args.noise)
    cold = run(all_cases[0], PanTiltLinkConfig(noise=args.noise, beta=1.2), 2, seed=0)
    print(f"kernels: {jit.mode()}; the process's first sample: {cold.first / 1e3:.1f} ms")
    print(f'two-axis session, {args.samples} samples per loop, noise {args.noise:g} V, '
          f'{args.repeats} rounds; us per sample (thread CPU): min / median, ratio of '
          'the medians to default; first: the first sample of a new session; worst: the '
          'dearest sample after it (median over rounds)')
    for label, jitter in (('exact stamps', 0.0), (f'+-{args.jitter:g} dt jitter',
                                                  args.jitter)):
        base = PanTiltLinkConfig(noise=args.noise, beta=1.2)
        link = replace(base, jitter=jitter * base.dt)
        got: dict[str, list[Timing]] = {c.name: [] for c in all_cases}
        for r in range(args.repeats):
            for case in all_cases:
                got[case.name].append(run(case, link, args.samples, seed=r))
        ref = statistics.median(t.per_sample for t in got['default'])
        print(f'\n{label}:')
        print(f'{"case":>14} | {"us per sample":>19} | {"ratio":>5} | {"first, us":>9} | '
              f'{"worst, ms":>9} | {"max rate, Hz":>12}')
        for name, timings in got.items():
            values = [t.per_sample for t in timings]
            med = statistics.median(values)
            first = statistics.median(t.first for t in timings)
            worst = statistics.median(t.worst for t in timings) / 1e3
            print(f'{name:>14} | {min(values):8.1f} / {med:8.1f} | {med / ref:5.2f} | '
                  f'{first:9.0f} | {worst:9.1f} | {1e6 / med:12.0f}')


if __name__ == '__main__':
    main()
