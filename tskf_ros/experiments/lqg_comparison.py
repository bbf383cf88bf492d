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

"""LQG against the paper's P controller on the scanning EKF: tracking % against beta, effort."""

import argparse
from concurrent.futures import ProcessPoolExecutor
import dataclasses
import math
from pathlib import Path
import sys
import time
from typing import Any, Iterator, Optional, Sequence

from matplotlib.figure import Figure
import numpy as np

from tskf_ros import led
from tskf_ros.experiments import arguments
from tskf_ros.experiments.alignment_ablation_report import bootstrap_ci
from tskf_ros.experiments.alignment_mc import save_figure, write_json

DEFAULT_BETAS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0)
# the controllers compared: the paper's P with Table I's P0 = diag(100, 1000), the P with
# the clipped prior diag(4, 25) (the LQG's x1, x2 information is no better), and the LQG
CLIPPED_P0 = ((4.0, 0.0), (0.0, 25.0))
EKF_CONFIGS = {'p': led.EKFConfig(), 'p_prior': led.EKFConfig(P0=CLIPPED_P0)}
CONTROLLERS = ('p', 'p_prior', 'lqg')
LABELS = {'p': 'EKF + P controller (paper, eq. (21), Table I P0)',
          'p_prior': 'EKF + P controller, P0 = diag(4, 25)',
          'lqg': 'EKF + drift + time-scale LQR'}
COLORS = {'p': 'tab:blue', 'p_prior': 'tab:green', 'lqg': 'tab:red'}
BOOTSTRAP = 1000                # resamples of the 95 % intervals (over runs)
_LQG = led.LQGConfig()
# the LQG with one part changed: what each part is worth
ABLATIONS = {
    'paper_scan': dataclasses.replace(_LQG, scan=led.SCAN_ANGLES, acquisition=()),
    'no_acquisition': dataclasses.replace(_LQG, acquisition=()),
    'no_bank': dataclasses.replace(_LQG, x2_starts=()),
    'no_drift': dataclasses.replace(_LQG, P0=(1.0, 4.0, 1e-12), Q=(0.0025, 0.01, 0.0)),
    'paper_Q': dataclasses.replace(_LQG, Q=(0.25, 1.0, 1e-5)),
    'gain_of_p': dataclasses.replace(_LQG, state_weight=0.5, input_weight=1.0),
}


def simulate_point(controller: str, *, beta: float, noise: float, runs: int, steps: int,
                   dt: float, seed: int, lqg: Optional[led.LQGConfig] = None
                   ) -> tuple[dict, np.ndarray]:
    """Run one controller (of CONTROLLERS) at one (beta, noise); return metrics, per-run |phi|."""
    link = led.TrackingLinkConfig(beta=beta, noise=noise, steps=steps, dt=dt)
    if lqg is not None:
        lqg = dataclasses.replace(lqg, dt=dt)
    kind = 'lqg' if controller == 'lqg' else 'p'
    ekf = dataclasses.replace(EKF_CONFIGS.get(controller, led.EKFConfig()), dt=dt)
    aligner = led.make_aligner('ekf', runs=runs, dt=dt, controller=kind, lqg=lqg, ekf=ekf)
    traj = led.simulate_tracking(aligner, link, np.random.default_rng(seed))
    angular, measure = led.tracking(traj)
    psi = traj.phi - traj.x2
    dpsi = np.vstack([np.diff(psi, axis=0), aligner.scan_offset - psi[-1:]])
    abs_phi = np.abs(led.wrap_degrees(traj.phi)).mean(axis=0)
    index = np.random.default_rng(seed + 1).integers(0, runs, size=(BOOTSTRAP, runs))
    record = {'beta_deg_per_s': beta, 'noise_v': noise,
              'angular': {'mean': float(angular.mean()), 'std': float(angular.std()),
                          'ci95': bootstrap_ci(angular, index)},
              'mean_abs_phi_deg_ci95': bootstrap_ci(abs_phi, index),
              'measure': {'mean': float(measure.mean()), 'std': float(measure.std())},
              'mean_abs_phi_deg': float(abs_phi.mean()),
              'lost_runs': int(np.sum(angular < 50.0)),
              'actuation_deg': float(np.abs(traj.command).sum(axis=0).mean()),
              'control_actuation_deg': float(np.abs(traj.command - dpsi).sum(axis=0).mean())}
    return record, abs_phi


def run_point(controller: str, **kwargs: Any) -> dict:
    """Run one controller at one (beta, noise); return its metrics (simulate_point)."""
    return simulate_point(controller, **kwargs)[0]


@dataclasses.dataclass(frozen=True)
class Task:
    """One point of the comparison: a controller and simulate_point's keyword arguments."""

    controller: str
    kwargs: dict


def run_task(task: Task) -> tuple[dict, np.ndarray]:
    """Run simulate_point for one task (a worker process's job)."""
    return simulate_point(task.controller, **task.kwargs)


def run_tasks(tasks: Sequence[Task], workers: int) -> Iterator[tuple[dict, np.ndarray]]:
    """Yield run_task of each task, in order, computed on `workers` processes."""
    if workers <= 1 or len(tasks) <= 1:
        yield from map(run_task, tasks)
        return
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
        yield from pool.map(run_task, tasks)


def phi_ratio(lqg: np.ndarray, p: np.ndarray, seed: int) -> dict:
    """Return mean|phi| of the LQG over that of P, with a paired 95 % bootstrap interval."""
    index = np.random.default_rng(seed + 2).integers(0, lqg.size, size=(BOOTSTRAP, lqg.size))
    ratios = lqg[index].mean(axis=1) / p[index].mean(axis=1)
    lo, hi = np.percentile(ratios, [2.5, 97.5])
    return {'ratio': float(lqg.mean() / p.mean()), 'ci95': [float(lo), float(hi)]}


def plot(betas: Sequence[float], results: dict, *, title: str) -> Figure:
    """Tracking % against beta, both metrics, both controllers (error bars: std / 5)."""
    fig = Figure(figsize=(7.5, 4.8))
    ax = fig.add_subplot()
    for name, points in results.items():
        for metric, style, what in (('angular', '-o', 'by angle'), ('measure', '--s',
                                                                    'by measurement')):
            mean = np.array([p[metric]['mean'] for p in points])
            std = np.array([p[metric]['std'] for p in points]) / 5.0
            ax.errorbar(betas, mean, yerr=std, fmt=style, ms=3.5, capsize=2, lw=1.2,
                        color=COLORS[name], label=f'{LABELS[name]}, {what}')
    ax.set_xlabel('drift rate beta (deg/s)')
    ax.set_ylabel('tracking percentage (%)')
    ax.set_ylim(0, 102)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc='lower left')
    fig.tight_layout()
    return fig


def table(results: dict) -> str:
    """Format the points as a plain-text table."""
    lines = [f'{"controller":>14} {"beta":>5} {"noise":>5} | {"track ang":>9} {"meas":>6} | '
             f'{"mean|phi|":>9} {"lost":>4} | {"actuation":>9} {"control":>8}']
    for name, points in results.items():
        for p in points:
            lines.append(f'{name:>14} {p["beta_deg_per_s"]:5.1f} {p["noise_v"]:5.2f} | '
                         f'{p["angular"]["mean"]:8.1f}% {p["measure"]["mean"]:5.1f}% | '
                         f'{p["mean_abs_phi_deg"]:9.2f} {p["lost_runs"]:4d} | '
                         f'{p["actuation_deg"]:9.1f} {p["control_actuation_deg"]:8.1f}')
    return '\n'.join(lines)


def parser() -> argparse.ArgumentParser:
    """Build the command-line interface."""
    p = argparse.ArgumentParser(prog='python -m tskf_ros.experiments.lqg_comparison',
                                description=__doc__.split('\n\n')[0])
    arguments.add_runs(p, 1000, 'point')
    p.add_argument('--betas',
                   type=arguments.numbers(0.0, arguments.MAX_RATE), default=list(DEFAULT_BETAS),
                   help='comma list of drift rates, deg/s (0,2,...,16)')
    p.add_argument('--noise', type=arguments.noise_volts, default=math.sqrt(led.PAPER_R_SYS[0][0]),
                   help='noise of the beta sweep, V (0.2: Table I R_sys)')
    p.add_argument('--effort-noise', type=arguments.noise_volts,
                   default=1.0, help='effort point noise, V (1)')
    p.add_argument('--effort-beta', type=arguments.rate_deg_s, default=2.8,
                   help='effort point drift rate, deg/s (2.8, Fig. 14)')
    arguments.add_run_options(p, dt=led.PAPER_DT)
    p.add_argument('--ablation', action='store_true',
                   help='also run the LQG variants of ABLATIONS at --ablation-beta (noise '
                        '--noise) and at the effort point')
    p.add_argument('--ablation-beta', type=arguments.rate_deg_s, default=14.0,
                   help='drift rate of the ablation at --noise, deg/s (14)')
    p.add_argument('--json', type=Path, help='write the results as JSON')
    p.add_argument('--png', type=Path, help='write tracking %% against beta')
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the comparison; return the exit status."""
    args = parser().parse_args(argv)
    if not (args.noise >= 0 and args.effort_noise >= 0):
        parser().error('the noise levels must be >= 0')
    common = {'runs': args.runs, 'steps': args.steps, 'dt': args.dt, 'seed': args.seed}
    start = time.perf_counter()
    # every point (controller, beta, noise): the sweep, the effort point, the ablation
    tasks = [Task(name, {'beta': beta, 'noise': args.noise, **common})
             for name in CONTROLLERS for beta in args.betas]
    tasks += [Task(name, {'beta': args.effort_beta, 'noise': args.effort_noise, **common})
              for name in CONTROLLERS]
    points = ((args.noise, args.ablation_beta), (args.effort_noise, args.effort_beta))
    if args.ablation:
        tasks += [Task('lqg', {'beta': beta, 'noise': noise, 'lqg': config, **common})
                  for config in ABLATIONS.values() for noise, beta in points]
    done = run_tasks(tasks, args.workers)
    sweep: dict = {name: [] for name in CONTROLLERS}
    effort = {}
    phi: dict = {name: [] for name in CONTROLLERS}      # per-run mean |phi|, each point
    for name in CONTROLLERS:
        for beta in args.betas:
            point, runs_phi = next(done)
            sweep[name].append(point)
            phi[name].append(runs_phi)
            print(f'[lqg_comparison] {name} beta {beta:g}: '
                  f'{sweep[name][-1]["angular"]["mean"]:.1f}%', file=sys.stderr, flush=True)
    for name in CONTROLLERS:
        effort[name], runs_phi = next(done)
        phi[name].append(runs_phi)
    # mean |phi| of the LQG over that of each P, at each beta and at the effort point
    ratios = {p: [phi_ratio(phi['lqg'][i], phi[p][i], args.seed) for i in range(len(phi[p]))]
              for p in ('p', 'p_prior')}
    ablation: dict = {}
    if args.ablation:
        for name in ABLATIONS:
            ablation[name] = [next(done)[0] for _ in points]
    elapsed = time.perf_counter() - start
    print(table(sweep))
    print(table({name: [point] for name, point in effort.items()}))
    if ablation:
        print(table(ablation))
    data = {'config': {**common, 'noise_v': args.noise, 'effort_noise_v': args.effort_noise,
                       'effort_beta_deg_per_s': args.effort_beta,
                       'controllers': list(CONTROLLERS),
                       'p_prior_P0': CLIPPED_P0},
            'betas_deg_per_s': list(args.betas), 'sweep': sweep, 'effort': effort,
            'ablation': ablation, 'elapsed_s': elapsed,
            'mean_abs_phi_ratio_lqg_over': {p: {'sweep': r[:-1], 'effort': r[-1]}
                                            for p, r in ratios.items()},
            'method': {'interval': '95 % percentile bootstrap over runs', 'resamples': BOOTSTRAP,
                       'ratio': 'paired over the same runs (common random numbers)'}}
    for p, r in ratios.items():
        print(f'mean |phi| LQG / {p} at the effort point: {r[-1]["ratio"]:.3f} '
              f'[{r[-1]["ci95"][0]:.3f}, {r[-1]["ci95"][1]:.3f}]')
    if args.json:
        write_json(args.json, data)
    if args.png:
        fig = plot(args.betas, sweep, title=f'Tracking against drift: noise {args.noise:g} V, '
                   f'{args.runs} runs of {args.steps} steps of {args.dt * 1000:g} ms '
                   '(error bars: std / 5)')
        save_figure(fig, args.png)
    return 0


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
