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

"""Monte Carlo comparison of LED alignment algorithms (Solanki et al. 2018, Fig. 8-10)."""

import argparse
import dataclasses
import math
from pathlib import Path
import sys
import time
from typing import Callable, Iterator, Optional, Sequence, TYPE_CHECKING

import numpy as np

from tskf_ros import led
from tskf_ros.bag.progress import bar
from tskf_ros.experiments import alignment_mc_two_axis, alignment_pat, monte_carlo, output
from tskf_ros.experiments.alignment_figures import plot_run, plot_tracking
from tskf_ros.experiments.alignment_mc_arguments import parser, PAT_ALGORITHMS
from tskf_ros.experiments.monte_carlo import (BATCH_RUNS, batches, PART_RUNS,  # noqa: F401
                                              Point)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Progress = Callable[[str], None]


class HoldLast:
    """
    A regular-sample view of an aligner: a missing measurement repeats the last one.

    This is what a filter that assumes regular samples gets from a sample-and-hold
    driver; the comparison shows what stamp-aware prediction over gaps buys.
    """

    def __init__(self, aligner: led.Aligner) -> None:
        self.aligner = aligner
        self.runs = aligner.runs
        self.last = np.full(self.runs, np.nan)

    @property
    def scan_offset(self) -> float:
        """Return the wrapped aligner's scan offset."""
        return self.aligner.scan_offset

    def step(self, stamp: float, z: led.Measurement) -> np.ndarray:
        """Replace missing entries by the last measurement and step the wrapped aligner."""
        z = led.as_measurement(z, self.runs)
        self.last = np.where(np.isfinite(z), z, self.last)
        return self.aligner.step(stamp, self.last)


def build(name: str, runs: int, link: led.TrackingLinkConfig, response: led.IncidenceResponse,
          ekf: led.EKFConfig, clip: bool, controller: str = 'p') -> led.Aligner:
    """Build the aligner for `name` (led.ALGORITHMS or 'ekf_hold'); the EKF's controller."""
    if name == 'ekf_hold':
        return HoldLast(led.make_aligner('ekf', runs=runs, dt=link.dt, response=response,
                                         ekf=ekf, controller=controller))
    return led.make_aligner(name, runs=runs, dt=link.dt, response=response, ekf=ekf, clip=clip,
                            controller=controller)


def evaluate(name: str, runs: int, link: led.TrackingLinkConfig, rng: np.random.Generator,
             response: led.IncidenceResponse, ekf: led.EKFConfig, clip: bool,
             controller: str = 'p') -> tuple[np.ndarray, np.ndarray]:
    """Return the tracking % (angular, measure) per run of one algorithm on one link."""
    aligner = build(name, runs, link, response, ekf, clip, controller)
    traj = led.simulate_tracking(aligner, link, rng, response)
    return led.tracking(traj, threshold=led.TRACKING_LEVEL * link.max_intensity)


def _empty(algorithms: Sequence[str]) -> dict:
    return {name: {**{metric: {'mean': [], 'std': []} for metric in ('angular', 'measure')},
                   **alignment_pat.empty_record()} for name in algorithms}


def _record(results: dict, name: str, angular: np.ndarray, measure: np.ndarray) -> None:
    for metric, values in (('angular', angular), ('measure', measure)):
        results[name][metric]['mean'].append(float(np.mean(values)))
        results[name][metric]['std'].append(float(np.std(values)))


@dataclasses.dataclass(frozen=True)
class Alignment:
    """The comparison's Experiment: the tracking % per run (angular, measure), the metrics."""

    # what tracking and the metrics read: the angle and the clean intensity
    keep: tuple[str, ...] = ('phi', 'clean')

    def build(self, points: Sequence[Point], runs: int) -> led.Aligner:
        """Return the aligner of points of one kind side by side (the supervised: recorded)."""
        first = points[0]
        if first.name in PAT_ALGORITHMS:
            R = np.repeat([alignment_pat.ekf_settings(first.name, p.link, first.ekf).R
                           for p in points], [p.runs for p in points], axis=0)
            return alignment_pat.build_pat(first.name, runs, first.link, first.response,
                                           first.ekf, first.clip, R=R)
        return build(first.name, runs, first.link, first.response, first.ekf, first.clip,
                     first.controller)

    def finish(self, aligner: led.Aligner) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """Return the supervisor's states and declared losses (steps, runs), or None."""
        if isinstance(aligner, alignment_pat.Recorded):
            return np.array(aligner.states), np.array(aligner.declared)
        return None

    def measure(self, traj: led.Trajectory, p: Point,
                end: Optional[tuple[np.ndarray, np.ndarray]],
                cols: slice) -> tuple[np.ndarray, np.ndarray, dict]:
        """Return the tracking % per run (angular, measure) and the metrics of point p."""
        angular, measure = led.tracking(traj, threshold=led.TRACKING_LEVEL
                                        * p.link.max_intensity)
        states, declared = (None, None) if end is None else (end[0][:, cols], end[1][:, cols])
        return angular, measure, alignment_pat.metrics(traj, states, declared,
                                                       blocked=p.link.blocked)

    def join(self, parts: list) -> tuple[np.ndarray, np.ndarray, dict]:
        """Return the measures of a point's parts together."""
        return (np.concatenate([g[0] for g in parts]), np.concatenate([g[1] for g in parts]),
                alignment_pat.join_metrics([g[2] for g in parts]))


ALIGNMENT = Alignment()


def run_point(p: Point) -> tuple[np.ndarray, np.ndarray, dict]:
    """Simulate one point; return the tracking % per run (angular, measure) and the metrics."""
    return run_batch([p])[0]


def run_batch(points: Sequence[Point]) -> list[tuple[np.ndarray, np.ndarray, dict]]:
    """Simulate points of one kind side by side (one aligner); return run_point of each."""
    return monte_carlo.run_batch(points, ALIGNMENT)


def run_points(points: Sequence[Point], workers: int,
               part_runs: Optional[int] = None, batch_runs: Optional[int] = None,
               scheduler: Optional[str] = None) -> Iterator[tuple]:
    """Yield run_point of each point, in order, on `workers` processes (monte_carlo)."""
    return monte_carlo.run_points(points, workers, ALIGNMENT, part_runs, batch_runs,
                                  scheduler)


def sweep(parameter: str, values: Sequence[float], *, runs: int, link: led.TrackingLinkConfig,
          seed: int, response: led.IncidenceResponse, ekf: led.EKFConfig,
          algorithms: Sequence[str] = led.ALGORITHMS, clip: bool = False,
          controller: str = 'p', progress: Optional[Progress] = None,
          workers: int = 1, scheduler: Optional[str] = None) -> dict:
    """
    Run every algorithm at each value of a LinkConfig field ('noise' or 'dropout').

    The points (value, algorithm) run on `workers` processes (or a Dask scheduler's
    workers); each starts its own generator from `seed`, so the results do not depend on
    the number of workers.
    """
    results = _empty(algorithms)
    start = time.perf_counter()
    # a progress bar over values x algorithms (stderr, a terminal only)
    tick = bar(len(values) * len(algorithms), f'alignment_mc {parameter}', 'point',
               progress is not None)
    points = [Point(name, runs, dataclasses.replace(link, **{parameter: float(value)}), seed,
                    response, ekf, clip, controller) for value in values for name in algorithms]
    done = run_points(points, workers, scheduler=scheduler)
    for i, value in enumerate(values):
        tic = time.perf_counter()
        parts = []
        for name in algorithms:
            angular, measure, m = next(done)
            _record(results, name, angular, measure)
            alignment_pat.record(results[name], m)
            parts.append(f'{name} {np.mean(angular):5.1f}%')
            tick.update(1)
        if progress is not None:
            progress(f'{parameter} {value:.2f} ({i + 1}/{len(values)}): ' + '  '.join(parts)
                     + f'  [{runs} runs, {time.perf_counter() - tic:.1f} s]')
    tick.close()
    elapsed = time.perf_counter() - start
    return {'results': results, 'elapsed_s': elapsed}


def _config_record(args: argparse.Namespace, response: led.IncidenceResponse) -> dict:
    return {'runs': args.runs, 'beta_deg_per_s': args.beta, 'steps': args.steps, 'dt_s': args.dt,
            'seed': args.seed, 'x2_0_deg': args.x2_0, 'cold_start_deg': args.cold_start,
            'blocked_s': list(args.blocked),
            'max_intensity_v': led.MAX_INTENSITY,
            'units_per_degree': response.units_per_degree, 'x1_floor': args.x1_floor,
            'clip_three_point': args.clip_three_point, 'controller': args.controller,
            'tracking': {'angle_deg': led.TRACKING_ANGLE,
                         'level_v': led.TRACKING_LEVEL * led.MAX_INTENSITY}}


# ---------------------------------------------------------------------------------------
# Output


def write_json(path: Path, data: dict) -> None:
    """Write data as JSON, atomically (NaN and inf become null)."""
    output.write_json(path, data)


def save_figure(fig: 'Figure', path: Path) -> None:
    """Save a matplotlib figure as PNG, atomically."""
    output.save_figure(fig, path, dpi=120)


def single_run(beta: float, args: argparse.Namespace, response: led.IncidenceResponse,
               ekf: led.EKFConfig) -> tuple[led.Trajectory, float, float]:
    """Run the EKF once (default noise: R_sys); return it and its tracking %."""
    link = led.TrackingLinkConfig(beta=beta, dt=args.dt, steps=args.steps, noise=args.run_noise,
                                  x2_0=args.x2_0, dropout=args.dropout)
    aligner = build('ekf', 1, link, response, ekf, False, args.controller)
    traj = led.simulate_tracking(aligner, link, np.random.default_rng(args.seed), response)
    angular, measure = led.tracking(traj)
    return traj, float(angular[0]), float(measure[0])


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the requested experiments; return the exit status."""
    axes = argparse.ArgumentParser(prog=parser().prog, add_help=False)
    axes.add_argument('--axes', type=int, choices=(1, 2), default=1)
    if axes.parse_known_args(argv)[0].axes == 2:
        return alignment_mc_two_axis.main(argv)
    try:
        return _main(parser().parse_args(argv))
    except monte_carlo.SchedulerError as exc:
        print(f'alignment_mc: {exc}', file=sys.stderr)
        return 1


def _main(args: argparse.Namespace) -> int:
    """Run the experiments of parsed arguments; return the exit status."""
    if not 0.0 <= args.dropout < 1.0 or any(not 0.0 <= d < 1.0 for d in args.dropout_levels):
        parser().error('dropout probabilities must be in [0, 1)')

    def progress(line: str) -> None:
        print(f'[alignment_mc] {line}', file=sys.stderr, flush=True)

    try:
        scale = led.LITERAL_UNITS_PER_DEGREE if args.literal_units else args.units_per_degree
        response = led.IncidenceResponse(units_per_degree=scale)
        ekf = led.EKFConfig(dt=args.dt, x1_floor=args.x1_floor)
        observable = led.observability(ekf.gain, ekf.scan)
    except led.AlignmentError as exc:
        print(f'alignment_mc: {exc}', file=sys.stderr)
        return 2
    if not (math.isfinite(args.cold_start) and 0.0 <= args.cold_start <= 180.0):
        parser().error('--cold-start must be in [0, 180] deg')
    if args.no_comparison and (args.json or args.png or args.acquisition_png):
        parser().error('--json, --png and --acquisition-png write the noise-level comparison, '
                       'which --no-comparison skips')
    if args.blocked and not (len(args.blocked) == 2 and args.blocked[0] < args.blocked[1]):
        parser().error(f'--blocked needs START,STOP in s with START < STOP, '
                       f'got {args.blocked}')
    if args.blocked and args.blocked[0] >= args.steps * args.dt:
        parser().error(f'--blocked {args.blocked[0]:g},{args.blocked[1]:g}: the blocked '
                       f'interval lies outside the run ({args.steps} steps of {args.dt:g} s: '
                       f'0 to {args.steps * args.dt:g} s)')
    names = args.algorithms or (led.ALGORITHMS + PAT_ALGORITHMS if args.controller == 'p'
                                else led.ALGORITHMS)
    unknown = set(names) - set(led.ALGORITHMS + PAT_ALGORITHMS)
    if unknown or (args.controller != 'p' and set(names) & set(PAT_ALGORITHMS)):
        parser().error(f'--algorithms: unknown {sorted(unknown)} or supervised with '
                       f'--controller {args.controller} (the supervisor steers the P controller)')
    link = led.TrackingLinkConfig(beta=args.beta, dt=args.dt, steps=args.steps,
                                  x2_0=0.0 if args.cold_start else args.x2_0,
                                  x2_0_spread=args.cold_start, dropout=args.dropout,
                                  blocked=tuple(args.blocked))
    common = {'runs': args.runs, 'seed': args.seed, 'response': response, 'ekf': ekf,
              'clip': args.clip_three_point, 'controller': args.controller,
              'progress': progress, 'workers': args.workers, 'scheduler': args.scheduler}
    if not observable.guaranteed:
        progress(f'note: {observable.message}')
    progress(f'g at {response.units_per_degree:.4g} fit units per degree; beta {args.beta:g} '
             f'deg/s; {args.steps} steps of {args.dt:g} s; {args.runs} runs per point')

    if not args.no_comparison:
        out = sweep('noise', args.noise_levels, link=link, algorithms=names, **common)
        progress(f'comparison done in {out["elapsed_s"]:.1f} s')
        data = {'noise_levels': list(args.noise_levels), 'results': out['results'],
                'config': {**_config_record(args, response), 'dropout': args.dropout},
                'elapsed_s': out['elapsed_s']}
        print(table('noise', args.noise_levels, out['results']))
        if args.json:
            write_json(args.json, data)
            progress(f'wrote {args.json}')
        if args.png:
            fig = plot_tracking(
                args.noise_levels, out['results'], xlabel='noise level (std of v, V)',
                title=f'beta = {args.beta:g} deg/s, {args.runs} runs, dropout {args.dropout:g},'
                      f' EKF controller {args.controller} (error bars: std / 5)')
            save_figure(fig, args.png)
            progress(f'wrote {args.png}')
        if args.acquisition_png:
            start = (f'cold start within +-{args.cold_start:g} deg' if args.cold_start
                     else f'known start x2_0 = {args.x2_0:g} deg')
            save_figure(alignment_pat.plot_acquisition(out['results'], title=(
                f'Acquisition time, {start}, noise {args.noise_levels[0]:g} V, '
                f'{args.runs} runs')), args.acquisition_png)
            progress(f'wrote {args.acquisition_png}')

    for path, beta in ((args.fig8, args.beta), (args.fig9, args.fig9_beta)):
        if path is None:
            continue
        traj, angular, measure = single_run(beta, args, response, ekf)
        fig = plot_run(traj, threshold=led.TRACKING_LEVEL * led.MAX_INTENSITY,
                       title=f'EKF ({args.controller}), beta = {beta:g} deg/s, '
                             f'noise {args.run_noise:g} V: '
                             f'tracking {angular:.1f}% (angle), {measure:.1f}% (measure)')
        save_figure(fig, path)
        progress(f'wrote {path} (beta {beta:g} deg/s: tracking {angular:.1f}%)')

    if args.pat_run:
        plink = dataclasses.replace(link, noise=args.run_noise, blocked=(8.0, 11.0))
        *_, traj, rec = alignment_pat.evaluate('ekf_pat', 1, plink,
                                               np.random.default_rng(args.seed), response, ekf,
                                               False)
        save_figure(alignment_pat.plot_pat_run(traj, rec, title=(
            f'ekf_pat, noise {args.run_noise:g} V, cold start within +-{args.cold_start:g} deg,'
            ' light blocked 8-11 s')), args.pat_run)
        progress(f'wrote {args.pat_run}')

    if args.dropout_png or args.dropout_json:
        names = (*led.ALGORITHMS, 'ekf_hold')
        dlink = dataclasses.replace(link, noise=args.dropout_noise, beta=args.dropout_beta)
        out = sweep('dropout', args.dropout_levels, link=dlink, algorithms=names, **common)
        progress(f'dropout sweep done in {out["elapsed_s"]:.1f} s')
        print(table('dropout', args.dropout_levels, out['results']))
        data = {'dropout_levels': list(args.dropout_levels), 'results': out['results'],
                'config': {**_config_record(args, response), 'noise': args.dropout_noise,
                           'beta_deg_per_s': args.dropout_beta},
                'elapsed_s': out['elapsed_s']}
        if args.dropout_json:
            write_json(args.dropout_json, data)
            progress(f'wrote {args.dropout_json}')
        if args.dropout_png:
            fig = plot_tracking(
                [100.0 * d for d in args.dropout_levels], out['results'],
                xlabel='probability of a missing measurement (%)',
                title=f'noise {args.dropout_noise:g} V, beta = {args.dropout_beta:g} deg/s, '
                      f'{args.runs} runs (error bars: std / 5)')
            save_figure(fig, args.dropout_png)
            progress(f'wrote {args.dropout_png}')
    return 0


def table(parameter: str, values: Sequence[float], results: dict) -> str:
    """Format a plain-text table of mean (std) angular and measure tracking %."""
    names = list(results)
    head = f'{parameter:>8} | ' + ' | '.join(f'{n + " ang/meas":>24}' for n in names)
    lines = [head, '-' * len(head)]
    for i, value in enumerate(values):
        cells = []
        for n in names:
            a, m = results[n]['angular'], results[n]['measure']
            cells.append(f'{a["mean"][i]:5.1f} ({a["std"][i]:4.1f}) / {m["mean"][i]:5.1f}'
                         f' ({m["std"][i]:4.1f})'.rjust(24))
        lines.append(f'{value:8.2f} | ' + ' | '.join(cells))
    return '\n'.join(lines)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
