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
import dataclasses
import math
from pathlib import Path
import sys
import time
from typing import Iterator, Optional, Sequence

from matplotlib.figure import Figure
import numpy as np

from tskf_ros import led
from tskf_ros.experiments import arguments, monte_carlo
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
BOOTSTRAP_CHUNK = 1 << 22       # entries of the bootstrap index drawn at a time (32 MB)
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


@dataclasses.dataclass
class RunValues:
    """What a point gives per run (runs,): tracking %, mean |phi| (deg), actuation (deg)."""

    angular: np.ndarray
    measure: np.ndarray
    abs_phi: np.ndarray
    actuation: np.ndarray           # sum of |command| over the steps
    control: np.ndarray             # sum of |command - the scan's own step| over the steps


def run_values(traj: led.Trajectory, scan_offset: float) -> RunValues:
    """Return the RunValues of a simulation (scan_offset: the aligner's, after it)."""
    angular, measure = led.tracking(traj)
    psi = traj.phi - traj.x2
    dpsi = np.vstack([np.diff(psi, axis=0), scan_offset - psi[-1:]])
    return RunValues(angular, measure, np.abs(led.wrap_degrees(traj.phi)).mean(axis=0),
                     np.abs(traj.command).sum(axis=0), np.abs(traj.command - dpsi).sum(axis=0))


def bootstrap_means(values: Sequence[np.ndarray], seed: int) -> list[np.ndarray]:
    """
    Return the BOOTSTRAP resampled means of each of values (runs,), one index for all.

    The index (BOOTSTRAP x runs, from default_rng(seed)) is drawn in rows of about 4 M
    entries: the same numbers as at once, in bounded memory.
    """
    runs = values[0].size
    rng = np.random.default_rng(seed)
    rows = max(1, BOOTSTRAP_CHUNK // runs)
    means: list[list[np.ndarray]] = [[] for _ in values]
    for start in range(0, BOOTSTRAP, rows):
        index = rng.integers(0, runs, size=(min(rows, BOOTSTRAP - start), runs))
        for m, v in zip(means, values):
            m.append(v[index].mean(axis=1))
    return [np.concatenate(m) for m in means]


def interval(means: np.ndarray) -> list[float]:
    """Return the 95 % percentile interval of bootstrap means."""
    lo, hi = np.percentile(means, [2.5, 97.5])
    return [float(lo), float(hi)]


def point_record(beta: float, noise: float, v: RunValues, seed: int) -> dict:
    """Return the metrics of one point from its RunValues (intervals: bootstrap over runs)."""
    angular_means, phi_means = bootstrap_means([v.angular, v.abs_phi], seed + 1)
    return {'beta_deg_per_s': beta, 'noise_v': noise,
            'angular': {'mean': float(v.angular.mean()), 'std': float(v.angular.std()),
                        'ci95': interval(angular_means)},
            'mean_abs_phi_deg_ci95': interval(phi_means),
            'measure': {'mean': float(v.measure.mean()), 'std': float(v.measure.std())},
            'mean_abs_phi_deg': float(v.abs_phi.mean()),
            'lost_runs': int(np.sum(v.angular < 50.0)),
            'actuation_deg': float(v.actuation.mean()),
            'control_actuation_deg': float(v.control.mean())}


def point(controller: str, *, beta: float, noise: float, runs: int, steps: int, dt: float,
          seed: int, lqg: Optional[led.LQGConfig] = None) -> monte_carlo.Point:
    """Return the Monte Carlo point of one controller (of CONTROLLERS) at (beta, noise)."""
    link = led.TrackingLinkConfig(beta=beta, noise=noise, steps=steps, dt=dt)
    ekf = dataclasses.replace(EKF_CONFIGS.get(controller, led.EKFConfig()), dt=dt)
    return monte_carlo.Point('ekf', runs, link, seed, led.IncidenceResponse(), ekf, False,
                             'lqg' if controller == 'lqg' else 'p',
                             lqg=None if lqg is None else dataclasses.replace(lqg, dt=dt))


def simulate_point(controller: str, *, beta: float, noise: float, runs: int, steps: int,
                   dt: float, seed: int, lqg: Optional[led.LQGConfig] = None
                   ) -> tuple[dict, np.ndarray]:
    """
    Run one controller at one (beta, noise) on one aligner; return metrics, per-run |phi|.

    The sequential path, all runs from default_rng(seed): what run_points gives a point
    of at most monte_carlo.PART_RUNS runs.
    """
    p = point(controller, beta=beta, noise=noise, runs=runs, steps=steps, dt=dt, seed=seed,
              lqg=lqg)
    aligner = COMPARISON.build([p], runs)
    traj = led.simulate_tracking(aligner, p.link, np.random.default_rng(seed))
    values = run_values(traj, aligner.scan_offset)
    return point_record(beta, noise, values, seed), values.abs_phi


@dataclasses.dataclass(frozen=True)
class Comparison:
    """The comparison's monte_carlo.Experiment: RunValues per point."""

    keep: tuple[str, ...] = ('phi', 'x2', 'clean', 'command')

    def build(self, points: Sequence[monte_carlo.Point], runs: int) -> led.Aligner:
        """Return the EKF with the points' controller, `runs` runs."""
        p = points[0]
        return led.make_aligner('ekf', runs=runs, dt=p.link.dt, response=p.response,
                                controller=p.controller, lqg=p.lqg, ekf=p.ekf)

    def finish(self, aligner: led.Aligner) -> float:
        """Return the aligner's scan offset after the simulation."""
        return aligner.scan_offset

    def measure(self, traj: led.Trajectory, p: monte_carlo.Point, end: float,
                cols: slice) -> RunValues:
        """Return the RunValues of point p."""
        return run_values(traj, end)

    def join(self, parts: list) -> RunValues:
        """Return the RunValues of a point's parts, in order."""
        return RunValues(*(np.concatenate([getattr(v, f.name) for v in parts])
                           for f in dataclasses.fields(RunValues)))


COMPARISON = Comparison()


def run_points(points: Sequence[monte_carlo.Point], workers: int,
               part_runs: Optional[int] = None, batch_runs: Optional[int] = None,
               scheduler: Optional[str] = None) -> Iterator[RunValues]:
    """Yield the RunValues of each point, in order, on `workers` processes (monte_carlo)."""
    return monte_carlo.run_points(points, workers, COMPARISON, part_runs, batch_runs,
                                  scheduler)


def phi_ratio(lqg: np.ndarray, p: np.ndarray, seed: int) -> dict:
    """Return mean|phi| of the LQG over that of P, with a paired 95 % bootstrap interval."""
    lqg_means, p_means = bootstrap_means([lqg, p], seed + 2)
    return {'ratio': float(lqg.mean() / p.mean()), 'ci95': interval(lqg_means / p_means)}


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
    arguments.add_scheduler(p)
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
    # every point (beta, noise) x controller: the sweep, the effort point, then the ablation
    where = [(beta, args.noise) for beta in args.betas] + [(args.effort_beta, args.effort_noise)]
    points = [point(name, beta=beta, noise=noise, **common)
              for beta, noise in where for name in CONTROLLERS]
    abl = ((args.ablation_beta, args.noise), (args.effort_beta, args.effort_noise))
    if args.ablation:
        points += [point('lqg', beta=beta, noise=noise, lqg=config, **common)
                   for config in ABLATIONS.values() for beta, noise in abl]
    try:
        return _compare(args, where, abl, run_points(points, args.workers,
                                                     scheduler=args.scheduler), start)
    except monte_carlo.SchedulerError as exc:
        print(f'lqg_comparison: {exc}', file=sys.stderr)
        return 1


def _compare(args: argparse.Namespace, where: list, abl: tuple, done: Iterator[RunValues],
             start: float) -> int:
    """Take the points' RunValues as they come; print and write the results."""
    common = {'runs': args.runs, 'steps': args.steps, 'dt': args.dt, 'seed': args.seed}
    sweep: dict = {name: [] for name in CONTROLLERS}
    effort = {}
    # mean |phi| of the LQG over that of each P, at each beta and at the effort point
    ratios: dict = {p: [] for p in ('p', 'p_prior')}
    for i, (beta, noise) in enumerate(where):
        phi = {}                    # per-run mean |phi| of each controller at this point
        for name in CONTROLLERS:
            values = next(done)
            record = point_record(beta, noise, values, args.seed)
            phi[name] = values.abs_phi
            if i < len(args.betas):
                sweep[name].append(record)
                print(f'[lqg_comparison] {name} beta {beta:g}: '
                      f'{record["angular"]["mean"]:.1f}%', file=sys.stderr, flush=True)
            else:
                effort[name] = record
        for p in ratios:
            ratios[p].append(phi_ratio(phi['lqg'], phi[p], args.seed))
    ablation: dict = {}
    if args.ablation:
        for name in ABLATIONS:
            ablation[name] = [point_record(beta, noise, next(done), args.seed)
                              for beta, noise in abl]
    elapsed = time.perf_counter() - start
    print(table(sweep))
    print(table({name: [rec] for name, rec in effort.items()}))
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
