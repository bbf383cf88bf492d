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
Ablation of the pointing experiment: what each ingredient adds to the plain EKF.

One ingredient at a time, at every noise level, on common random numbers: the prior
(Table I's P0 = diag(100, 1000) -> the clipped diag(4, 25)), the noise (Table I's
R = 1 V^2 -> R = sigma^2 of the link), the supervisor (hold, search, re-acquire:
tskf_ros.led.supervisor) and the LQG controller (tskf_ros.led.lqg_alignment, given the
same prior and R); the baselines with and without the supervisor.  95 % intervals by a
percentile bootstrap over runs (the steps of a run are correlated, the runs are not);
the gain of a row over its parent by a paired bootstrap over the same runs.
"""

import argparse
from concurrent.futures import ProcessPoolExecutor
import dataclasses
from dataclasses import dataclass
from pathlib import Path
import sys
import time
from typing import Optional, Sequence

import numpy as np

from tskf_ros import led
from tskf_ros.experiments import alignment_ablation_report as report
from tskf_ros.experiments import alignment_pat, arguments
from tskf_ros.experiments.alignment_mc_arguments import DEFAULT_NOISE_LEVELS
from tskf_ros.led.supervisor import Supervisor, SupervisorConfig

CLIPPED_P0 = ((4.0, 0.0), (0.0, 25.0))        # Table I's P0 clipped as the supervisor does
LQG_B_VAR = 0.1                                # the LQG's own prior variance of the drift b
BOOTSTRAP = 2000                               # bootstrap resamples


@dataclass(frozen=True)
class Row:
    """One configuration of the ablation: a tracker and the ingredients it is given."""

    name: str
    tracker: str                   # 'ekf' (P controller), 'lqg', 'hill_climbing', 'three_point'
    prior: bool = False            # P0 = diag(4, 25) (Table I: diag(100, 1000))
    matched_r: bool = False        # R = sigma^2 (Table I: 1 V^2)
    supervisor: bool = False       # hold, search, re-acquire
    parent: Optional[str] = None   # the row it adds one ingredient to

    @property
    def label(self) -> str:
        """Describe the row: the tracker and its ingredients."""
        base = {'ekf': 'EKF + P', 'lqg': 'EKF + LQG', 'hill_climbing': 'hill-climbing',
                'three_point': 'three-point'}[self.tracker]
        parts = [p for p, on in (('prior', self.prior), ('R = sigma^2', self.matched_r),
                                 ('supervisor', self.supervisor)) if on]
        return base + (' + ' + ' + '.join(parts) if parts else '')


ROWS = (
    Row('ekf', 'ekf'),
    Row('ekf+prior', 'ekf', prior=True, parent='ekf'),
    Row('ekf+prior+R', 'ekf', prior=True, matched_r=True, parent='ekf+prior'),
    Row('ekf+prior+R+sup', 'ekf', prior=True, matched_r=True, supervisor=True,
        parent='ekf+prior+R'),
    Row('lqg+prior+R', 'lqg', prior=True, matched_r=True, parent='ekf+prior+R'),
    Row('ekf+R', 'ekf', matched_r=True, parent='ekf'),
    Row('ekf+sup', 'ekf', supervisor=True, parent='ekf'),
    Row('hill', 'hill_climbing'),
    Row('hill+sup', 'hill_climbing', supervisor=True, parent='hill'),
    Row('3pt', 'three_point'),
    Row('3pt+sup', 'three_point', supervisor=True, parent='3pt'),
)
ROW = {row.name: row for row in ROWS}


def build(row: Row, runs: int, link: led.TrackingLinkConfig,
          response: led.IncidenceResponse) -> led.Aligner:
    """Build the aligner of `row` for `runs` runs on `link` (R = sigma^2: sigma >= MIN_NOISE)."""
    r = max(link.noise, alignment_pat.MIN_NOISE) ** 2 if row.matched_r else led.PAPER_R[0][0]
    if row.tracker == 'lqg':
        P0 = CLIPPED_P0 if row.prior else led.PAPER_P0
        lqg = led.LQGConfig(dt=link.dt, R=r, P0=(P0[0][0], P0[1][1], LQG_B_VAR))
        return led.make_aligner('ekf', runs=runs, dt=link.dt, response=response,
                                controller='lqg', lqg=lqg)
    ekf = led.EKFConfig(dt=link.dt, P0=CLIPPED_P0 if row.prior else led.PAPER_P0,
                        R=((r, 0.0), (0.0, r)))
    tracker = led.make_aligner(row.tracker, runs=runs, dt=link.dt, response=response, ekf=ekf)
    if not row.supervisor:
        return tracker
    # the known start of the paper: tracking from x0, P0; clip_prior only where the row
    # has the prior, so that the supervisor alone does not bring it
    config = SupervisorConfig(start='tracking', clip_prior=row.prior)
    assert not isinstance(tracker, led.LQGAligner)
    return alignment_pat.Recorded(Supervisor(tracker, config, response))


@dataclass(frozen=True)
class Cell:
    """One row at one noise level: the task of one worker."""

    row: str
    noise: float
    runs: int
    seed: int
    link: led.TrackingLinkConfig


def run_cell(cell: Cell) -> dict:
    """Simulate one cell; return per-run angular %, out of the cone at the end, mean |phi|."""
    link = dataclasses.replace(cell.link, noise=cell.noise)
    response = led.IncidenceResponse()
    aligner = build(ROW[cell.row], cell.runs, link, response)
    traj = led.simulate_tracking(aligner, link, np.random.default_rng(cell.seed), response)
    angular, _ = led.tracking(traj, threshold=led.TRACKING_LEVEL * link.max_intensity)
    phi = np.abs(led.wrap_degrees(traj.phi))
    return {'angular': angular, 'lost': phi[-1] > led.TRACKING_ANGLE,
            'mean_abs_phi': phi.mean(axis=0)}


def run_cells(cells: Sequence[Cell], workers: int) -> list[dict]:
    """Run the cells, in order, on `workers` processes (1: in this one)."""
    if workers <= 1 or len(cells) <= 1:
        return [run_cell(c) for c in cells]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(run_cell, cells))


def parser() -> argparse.ArgumentParser:
    """Build the command-line interface."""
    p = argparse.ArgumentParser(prog='python -m tskf_ros.experiments.alignment_ablation',
                                description=__doc__.split('\n\n')[0])
    arguments.add_runs(p, 2000, 'row and noise level')
    arguments.add_noise_levels(p, DEFAULT_NOISE_LEVELS)
    p.add_argument('--rows', type=lambda t: [a for a in t.split(',') if a],
                   default=[row.name for row in ROWS],
                   help='comma list of the rows (default: all: ' + ','.join(ROW) + ')')
    p.add_argument('--beta', type=arguments.rate_deg_s, default=1.2,
                   help='disturbance rate, deg/s (1.2)')
    arguments.add_run_options(p)
    p.add_argument('--json', type=Path, help='write the results as JSON')
    p.add_argument('--markdown', type=Path, help='write the tables as a markdown page')
    p.add_argument('--png', type=Path, help='write tracking %% against noise, with intervals')
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the ablation; return the exit status."""
    args = parser().parse_args(argv)
    unknown = [r for r in args.rows if r not in ROW]
    if unknown:
        parser().error(f'--rows: unknown {unknown}; expected some of {list(ROW)}')
    rows = [ROW[r] for r in args.rows]
    link = led.TrackingLinkConfig(beta=args.beta, steps=args.steps, x2_0=5.0)
    cells = [Cell(row.name, float(noise), args.runs, args.seed, link)
             for row in rows for noise in args.noise_levels]
    start = time.perf_counter()
    print(f'[alignment_ablation] {len(cells)} cells of {args.runs} runs on {args.workers} '
          'processes', file=sys.stderr, flush=True)
    out = run_cells(cells, args.workers)
    elapsed = time.perf_counter() - start
    per_run = {row.name: out[i * len(args.noise_levels):(i + 1) * len(args.noise_levels)]
               for i, row in enumerate(rows)}
    data = report.summarise(rows, args.noise_levels, per_run,
                            rng=np.random.default_rng(args.seed + 1), resamples=BOOTSTRAP)
    data['config'] = {'runs': args.runs, 'seed': args.seed, 'beta_deg_per_s': args.beta,
                      'steps': args.steps, 'dt_s': link.dt, 'x2_0_deg': link.x2_0,
                      'clipped_P0': CLIPPED_P0, 'lqg_b_var': LQG_B_VAR,
                      'min_noise_v': alignment_pat.MIN_NOISE, 'workers': args.workers}
    data['elapsed_s'] = elapsed
    print(report.text_table(data))
    print(f'[alignment_ablation] done in {elapsed:.1f} s', file=sys.stderr)
    if args.json:
        report.write_json(args.json, data)
    if args.markdown:
        report.write_markdown(args.markdown, data, command=_command(args))
    if args.png:
        report.save_figure(report.plot(data), args.png)
    return 0


def _command(args: argparse.Namespace) -> str:
    parts = ['python -m tskf_ros.experiments.alignment_ablation', f'--runs {args.runs}',
             f'--seed {args.seed}']
    for flag in ('json', 'markdown', 'png'):
        if getattr(args, flag):
            parts.append(f'--{flag} {getattr(args, flag)}')
    return ' \\\n    '.join(parts)


__all__ = ['build', 'Cell', 'CLIPPED_P0', 'main', 'parser', 'Row', 'ROWS', 'run_cell',
           'run_cells']

if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
