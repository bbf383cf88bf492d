"""LQG against the paper's P controller on the scanning EKF: tracking % against beta, effort."""

import argparse
import dataclasses
import math
from pathlib import Path
import sys
import time
from typing import Optional, Sequence

from matplotlib.figure import Figure
import numpy as np

from tskf_ros import led
from tskf_ros.experiments import arguments
from tskf_ros.experiments.alignment_mc import save_figure, write_json

DEFAULT_BETAS = (0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0)
LABELS = {'p': 'EKF + P controller (paper, eq. (21))', 'lqg': 'EKF + drift + time-scale LQR'}
COLORS = {'p': 'tab:blue', 'lqg': 'tab:red'}
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


def run_point(controller: str, *, beta: float, noise: float, runs: int, steps: int, dt: float,
              seed: int, lqg: Optional[led.LQGConfig] = None) -> dict:
    """Run one controller at one (beta, noise); return its metrics (see the docstring)."""
    link = led.TrackingLinkConfig(beta=beta, noise=noise, steps=steps, dt=dt)
    if lqg is not None:
        lqg = dataclasses.replace(lqg, dt=dt)
    aligner = led.make_aligner('ekf', runs=runs, dt=dt, controller=controller, lqg=lqg)
    traj = led.simulate_tracking(aligner, link, np.random.default_rng(seed))
    angular, measure = led.tracking(traj)
    psi = traj.phi - traj.x2
    dpsi = np.vstack([np.diff(psi, axis=0), aligner.scan_offset - psi[-1:]])
    return {'beta_deg_per_s': beta, 'noise_v': noise,
            'angular': {'mean': float(angular.mean()), 'std': float(angular.std())},
            'measure': {'mean': float(measure.mean()), 'std': float(measure.std())},
            'mean_abs_phi_deg': float(np.abs(led.wrap_degrees(traj.phi)).mean()),
            'lost_runs': int(np.sum(angular < 50.0)),
            'actuation_deg': float(np.abs(traj.command).sum(axis=0).mean()),
            'control_actuation_deg': float(np.abs(traj.command - dpsi).sum(axis=0).mean())}


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
    p.add_argument('--runs', type=arguments.count(1, arguments.MAX_RUNS), default=1000,
                   help='runs per point (1000)')
    p.add_argument('--betas',
                   type=arguments.numbers(0.0, arguments.MAX_RATE), default=list(DEFAULT_BETAS),
                   help='comma list of drift rates, deg/s (0,2,...,16)')
    p.add_argument('--noise', type=arguments.noise_volts, default=math.sqrt(led.PAPER_R_SYS[0][0]),
                   help='noise of the beta sweep, V (0.2: Table I R_sys)')
    p.add_argument('--effort-noise', type=arguments.noise_volts,
                   default=1.0, help='effort point noise, V (1)')
    p.add_argument('--effort-beta', type=arguments.rate_deg_s, default=2.8,
                   help='effort point drift rate, deg/s (2.8, Fig. 14)')
    p.add_argument('--steps', type=arguments.count(1, arguments.MAX_STEPS), default=400,
                   help='steps per run (400 = 20 s)')
    p.add_argument('--dt', type=arguments.number(0.0, arguments.MAX_DT, open_low=True),
                   default=led.PAPER_DT, help='time step, s (0.05)')
    p.add_argument('--seed', type=arguments.seed, default=0)
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
    sweep: dict = {name: [] for name in led.CONTROLLERS}
    effort = {}
    for name in led.CONTROLLERS:
        for beta in args.betas:
            sweep[name].append(run_point(name, beta=beta, noise=args.noise, **common))
            print(f'[lqg_comparison] {name} beta {beta:g}: '
                  f'{sweep[name][-1]["angular"]["mean"]:.1f}%', file=sys.stderr, flush=True)
        effort[name] = run_point(name, beta=args.effort_beta, noise=args.effort_noise, **common)
    ablation: dict = {}
    if args.ablation:
        points = ((args.noise, args.ablation_beta), (args.effort_noise, args.effort_beta))
        for name, config in ABLATIONS.items():
            ablation[name] = [run_point('lqg', beta=beta, noise=noise, lqg=config, **common)
                              for noise, beta in points]
    elapsed = time.perf_counter() - start
    print(table(sweep))
    print(table({name: [point] for name, point in effort.items()}))
    if ablation:
        print(table(ablation))
    data = {'config': {**common, 'noise_v': args.noise, 'effort_noise_v': args.effort_noise,
                       'effort_beta_deg_per_s': args.effort_beta,
                       'controllers': list(led.CONTROLLERS)},
            'betas_deg_per_s': list(args.betas), 'sweep': sweep, 'effort': effort,
            'ablation': ablation, 'elapsed_s': elapsed}
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
