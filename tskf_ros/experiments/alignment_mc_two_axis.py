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
Monte Carlo comparison of two-axis (pan-tilt) LED alignment: `alignment_mc --axes 2`.

Every method runs the closed loop of tskf_ros.led.two_axis.pan_tilt_simulation at each
noise level from one seed (common random numbers: the methods see the same links).  Per
method and level, with the JSON keys of one axis: the tracking % by angle (the receiver's
off-axis angle within 15 deg) and by measure (clean intensity >= 0.6 V), and the pointing
metrics of alignment_pat (loss at the end, acquisition, re-acquisition); in addition 95 %
intervals (a percentile bootstrap over runs for means, Wilson's for proportions) and the
RMS error of the mean pointing per axis: azimuth (the cross-elevation angle on the sky,
wrap(a - a_s) cos e_s) and elevation (e - e_s), in degrees.
"""

import argparse
from concurrent.futures import ProcessPoolExecutor
import dataclasses
from pathlib import Path
import sys
import time
from typing import Any, Callable, Iterator, Optional, Sequence

import numpy as np

from tskf_ros import led
from tskf_ros.bag.progress import bar
from tskf_ros.experiments import alignment_pat, arguments, monte_carlo, output
from tskf_ros.experiments.alignment_ablation_report import bootstrap_ci, wilson
from tskf_ros.experiments.alignment_mc_arguments import DEFAULT_NOISE_LEVELS
from tskf_ros.experiments.alignment_mc_two_axis_figure import plot_two_axis
from tskf_ros.led.two_axis.aligners import make_two_axis_aligner
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig
from tskf_ros.led.two_axis.pan_tilt_baselines import FourPointAveraging, TwoAxisHillClimbing
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_simulation import (PanTiltTrajectory, simulate_pan_tilt,
                                                       TwoAxisAligner)
from tskf_ros.led.two_axis.radial_response import RadialResponse

# name -> what it is, for --help and the JSON
METHODS = {
    'conical_ekf_pat': 'conical-scan EKF, P controller per axis, with the supervisor',
    'conical_lqg': 'conical-scan EKF with drift states, LQG per axis',
    'conical_ekf': 'conical-scan EKF, P controller per axis (no supervisor)',
    'hill_climbing': 'hill climbing, axes alternating (gamma = 2 deg)',
    'four_point': 'four-point averaging, eq. (26) per axis (gamma = 2 deg)',
}
CONICAL = ('conical_ekf', 'conical_ekf_pat', 'conical_lqg')
# the comparison: the EKF with the supervisor, the LQG, the two baselines
DEFAULT_METHODS = ('conical_ekf_pat', 'conical_lqg', 'hill_climbing', 'four_point')
AXES = ('azimuth', 'elevation')
RESAMPLES = 2000              # bootstrap resamples of the runs
Progress = Callable[[str], None]


def build(name: str, runs: int, link: PanTiltLinkConfig, response: RadialResponse, *,
          clip: bool, ekf: Optional[ConicalEKFConfig] = None) -> TwoAxisAligner:
    """Build the method `name` (one of METHODS) for `runs` runs of `link` (ekf: CONICAL's)."""
    if name in CONICAL:
        # R from the link's noise, as ekf_pat's in one axis (at least MIN_NOISE: R > 0); a
        # cold start searches first (the supervised EKF)
        start = 'acquiring' if link.cone > 0.0 and name == 'conical_ekf_pat' else 'tracking'
        return make_two_axis_aligner(name, runs=runs, dt=link.dt, response=response,
                                     noise=max(link.noise, alignment_pat.MIN_NOISE),
                                     start=start, joints0=(0.0, link.elevation0), ekf=ekf)
    if name == 'hill_climbing':
        return TwoAxisHillClimbing(runs=runs, dt=link.dt)
    if name == 'four_point':
        return FourPointAveraging(runs=runs, dt=link.dt, clip=clip)
    raise led.AlignmentError(f'unknown method {name!r}; expected one of {list(METHODS)}')


def default_methods() -> list[str]:
    """Return the DEFAULT_METHODS that can be built (conical_ekf if the supervised cannot)."""
    names = [name for name in DEFAULT_METHODS if available(name)]
    return names if 'conical_ekf_pat' in names else ['conical_ekf'] + names


def available(name: str) -> bool:
    """Tell whether the method `name` can be built here."""
    try:
        build(name, 1, PanTiltLinkConfig(), RadialResponse(), clip=False)
    except led.AlignmentError:
        return False
    return True


class Recording:
    """An aligner whose supervisor's states and declared losses (if it has them) are kept."""

    def __init__(self, aligner: TwoAxisAligner) -> None:
        self.aligner = aligner
        self.runs = aligner.runs
        self.states: list[np.ndarray] = []
        self.declared: list[np.ndarray] = []

    @property
    def scan_offset(self) -> np.ndarray:
        """Return the aligner's scan offset."""
        return self.aligner.scan_offset

    def step(self, stamp: float, z: led.Measurement) -> np.ndarray:
        """Step the aligner; keep its state and declared losses when it is supervised."""
        turn = self.aligner.step(stamp, z)
        if hasattr(self.aligner, 'state') and hasattr(self.aligner, 'declared'):
            self.states.append(np.array(getattr(self.aligner, 'state')))
            self.declared.append(np.array(getattr(self.aligner, 'declared')))
        return turn


@dataclasses.dataclass(frozen=True)
class Point:
    """One method on one link: the task of one worker process."""

    name: str
    runs: int
    link: PanTiltLinkConfig
    seed: int
    response: RadialResponse
    clip: bool
    # the conical-scan EKF's settings (its noise and dt are the link's); None: the default
    ekf: Optional[ConicalEKFConfig] = None


@dataclasses.dataclass
class PointResult:
    """Per run: tracking % (angle, measure), RMS error per axis (runs, 2); the metrics."""

    angular: np.ndarray
    measure: np.ndarray
    rms: np.ndarray
    metrics: dict
    # windows whose smoothing failed (the filter's estimate kept); None: no smoother
    smoothing_failures: Optional[int] = None


def simulate(p: Point) -> tuple[PanTiltTrajectory, Recording]:
    """Run one point's closed loop from its seed; return the trajectory and the record."""
    aligner = Recording(build(p.name, p.runs, p.link, p.response, clip=p.clip, ekf=p.ekf))
    traj = simulate_pan_tilt(aligner, p.link, np.random.default_rng(p.seed), p.response)
    return traj, aligner


def run_point(p: Point) -> PointResult:
    """Simulate one point and reduce it to per-run numbers."""
    traj, rec = simulate(p)
    angular = 100.0 * np.mean(traj.theta <= led.TRACKING_ANGLE, axis=0)
    measure = 100.0 * np.mean(traj.clean >= led.TRACKING_LEVEL * p.link.max_intensity, axis=0)
    rms = np.sqrt(np.mean(traj.error ** 2, axis=0))
    supervised = bool(rec.states)
    m = alignment_pat.angle_metrics(traj.t, traj.theta,
                                    np.array(rec.states) if supervised else None,
                                    np.array(rec.declared) if supervised else None,
                                    blocked=p.link.blocked)
    failures = getattr(getattr(rec.aligner, 'tracker', rec.aligner), 'smoothing_failures', None)
    return PointResult(angular, measure, rms, m,
                       None if failures is None else int(failures))


def run_points(points: Sequence[Point], workers: int,
               scheduler: Optional[str] = None) -> Iterator[PointResult]:
    """
    Yield run_point of each point, in order, computed on `workers` processes.

    scheduler: the address of a Dask scheduler (e.g. tcp://host:8786), whose workers run
    the points instead (they need this package), as one axis's monte_carlo.run_points;
    raises monte_carlo.SchedulerError if it cannot be used.  Each point draws from its own
    seed, so the results are the same wherever it runs.
    """
    if scheduler is not None:
        with monte_carlo.dask_client(scheduler) as client:
            futures = client.map(run_point, list(points), pure=False)
            yield from (f.result() for f in futures)
        return
    if workers <= 1 or len(points) <= 1:
        yield from map(run_point, points)
        return
    with ProcessPoolExecutor(max_workers=min(workers, len(points))) as pool:
        yield from pool.map(run_point, points)


def empty_entry() -> dict:
    """Return one method's lists, filled one noise level at a time by record()."""
    mean_ci: Callable[[], dict] = lambda: {'mean': [], 'ci95': []}    # noqa: E731
    return {'angular': {'mean': [], 'std': [], 'ci95': []},
            'measure': {'mean': [], 'std': [], 'ci95': []},
            **alignment_pat.empty_record(),
            'lost_at_end_ci95': [], 'acquired_within_10s_ci95': [],
            'smoothing_failures': [],
            'rms_error_deg': {axis: mean_ci() for axis in AXES}}


def record(entry: dict, r: PointResult, index: np.ndarray) -> None:
    """Append one noise level's numbers; index (resamples, runs) draws the bootstrap."""
    for key, values in (('angular', r.angular), ('measure', r.measure)):
        entry[key]['mean'].append(float(np.mean(values)))
        entry[key]['std'].append(float(np.std(values)))
        entry[key]['ci95'].append(bootstrap_ci(values, index))
    alignment_pat.record(entry, r.metrics)
    runs = r.angular.size
    lost = int(round(r.metrics['lost_at_end'] * runs))
    entry['lost_at_end_ci95'].append(wilson(lost, runs))
    entry['smoothing_failures'].append(r.smoothing_failures)
    acq = r.metrics['acquisition']
    within = int(np.count_nonzero(acq.observed & (acq.times <= alignment_pat.ACQUIRED_WITHIN)))
    entry['acquired_within_10s_ci95'].append(wilson(within, acq.times.size)
                                             if acq.times.size else None)
    for i, axis in enumerate(AXES):
        entry['rms_error_deg'][axis]['mean'].append(float(np.mean(r.rms[:, i])))
        entry['rms_error_deg'][axis]['ci95'].append(bootstrap_ci(r.rms[:, i], index))


def sweep(noise_levels: Sequence[float], methods: Sequence[str], *, runs: int,
          link: PanTiltLinkConfig, seed: int, response: RadialResponse, clip: bool,
          progress: Optional[Progress] = None, workers: int = 1,
          scheduler: Optional[str] = None, ekf: Optional[ConicalEKFConfig] = None) -> dict:
    """Run every method at every noise level (run_points); return {'results', 'elapsed_s'}."""
    results = {name: empty_entry() for name in methods}
    index = np.random.default_rng([seed, 1]).integers(0, runs, size=(RESAMPLES, runs))
    start = time.perf_counter()
    tick = bar(len(noise_levels) * len(methods), 'alignment_mc two axes', 'point',
               progress is not None)
    points = [Point(name, runs, dataclasses.replace(link, noise=float(noise)), seed, response,
                    clip, ekf) for noise in noise_levels for name in methods]
    done = run_points(points, workers, scheduler)
    for i, noise in enumerate(noise_levels):
        tic = time.perf_counter()
        parts = []
        for name in methods:
            r = next(done)
            record(results[name], r, index)
            parts.append(f'{name} {np.mean(r.angular):5.1f}%')
            tick.update(1)
        if progress is not None:
            progress(f'noise {noise:.2f} ({i + 1}/{len(noise_levels)}): ' + '  '.join(parts)
                     + f'  [{runs} runs, {time.perf_counter() - tic:.1f} s]')
    tick.close()
    return {'results': results, 'elapsed_s': time.perf_counter() - start}


def table(noise_levels: Sequence[float], results: dict) -> str:
    """Format tracking % by angle, mean [95 % interval], and the share lost at the end."""
    names = list(results)
    head = f'{"noise":>6} | ' + ' | '.join(f'{n + " % [95%] lost":>30}' for n in names)
    lines = [head, '-' * len(head)]
    for i, noise in enumerate(noise_levels):
        cells = []
        for n in names:
            a = results[n]['angular']
            lo, hi = a['ci95'][i]
            cells.append(f'{a["mean"][i]:5.1f} [{lo:5.1f}, {hi:5.1f}] '
                         f'{results[n]["lost_at_end"][i]:6.3f}'.rjust(30))
        lines.append(f'{noise:6.2f} | ' + ' | '.join(cells))
    return '\n'.join(lines)


def parser() -> argparse.ArgumentParser:
    """Build the two-axis command line."""
    p = argparse.ArgumentParser(prog='python -m tskf_ros.experiments.alignment_mc --axes 2',
                                description=__doc__.split('\n\n')[0])
    p.add_argument('--axes', type=int, choices=(2,), default=2, help='2: this experiment')
    arguments.add_runs(p, 1000, 'noise level and method')
    arguments.add_noise_levels(p, DEFAULT_NOISE_LEVELS)
    p.add_argument('--beta', type=arguments.rate_deg_s, default=1.2,
                   help='drift rate per joint axis, deg/s (1.2)')
    arguments.add_run_options(p, dt=led.PAPER_DT)
    arguments.add_scheduler(p)
    p.add_argument('--dropout', type=arguments.number(0.0, 0.99), default=0.0,
                   help='probability that a sample is missing (0)')
    p.add_argument('--jitter', type=arguments.number(0.0, 1.0), default=0.0, metavar='S',
                   help='stamps k dt + U(-S, S), S < dt/2: the filter takes mu from them, the '
                        'plant moves by the elapsed time (0)')
    p.add_argument('--offset0', type=arguments.number(0.0, 90.0), default=5.0, metavar='DEG',
                   help='off-axis angle of the mean pointing at the start, random direction '
                        '(5)')
    p.add_argument('--cold-start', type=arguments.number(0.0, 60.0), default=0.0,
                   metavar='DEG', help='start uniform in a cone of DEG instead of --offset0 '
                                       '(0: off)')
    p.add_argument('--methods', '--algorithms', dest='methods',
                   type=lambda t: [a for a in t.split(',') if a],
                   default=None,
                   help='comma list of the methods compared (default: '
                        + ','.join(DEFAULT_METHODS) + '), of: ' + ', '.join(
                       f'{k} ({v})' for k, v in METHODS.items()))
    p.add_argument('--dim-radius', type=arguments.number(0.0, 14.9),
                   default=ConicalEKFConfig.dim_radius, metavar='DEG',
                   help='the conical scan widens to DEG as the estimated peak x1hat g_r(0) '
                        'falls from --dim-peak to half of it, and narrows back to 4 deg at a '
                        'quarter of it (0: off, r stays 4 deg; '
                        f'default {ConicalEKFConfig.dim_radius:g})')
    p.add_argument('--dim-peak', type=arguments.number(0.0, 100.0, open_low=True),
                   default=ConicalEKFConfig.dim_peak, metavar='V',
                   help='the estimated peak under which the scan widens, V '
                        f'({ConicalEKFConfig.dim_peak:g})')
    p.add_argument('--wide', type=arguments.number(0.0, 90.0), default=ConicalEKFConfig.wide,
                   metavar='DEG',
                   help="the EKF's runs whose pointing prior is wider than DEG take the "
                        'Gauss-Hermite regression instead of the Jacobian (0: off, the '
                        'default; 2.5: a consistent covariance from 1 V, as many lost at 1 V, '
                        'more at 1.5 and 2 V)')
    p.add_argument('--smooth-after', type=arguments.count(0, 400),
                   default=ConicalEKFConfig.smooth_after, metavar='N',
                   help="at the EKF's N-th sample, the runs not handed over since the start "
                        "take the iterated smoother's estimate over those samples (0: off; "
                        f'default {ConicalEKFConfig.smooth_after})')
    p.add_argument('--smooth-every', type=arguments.count(0, 400),
                   default=ConicalEKFConfig.smooth_every, metavar='N',
                   help='after that, the smoother goes over each N samples again, from the '
                        "EKF's estimate where they begin (0: once only; "
                        f'default {ConicalEKFConfig.smooth_every})')
    p.add_argument('--clip-four-point', action='store_true',
                   help='clip gamma_p of eq. (26) to [-gamma, gamma] (as --clip-three-point)')
    p.add_argument('--run-noise', type=arguments.noise_volts, default=1.0,
                   help="noise of the figure's single run, V (1.0)")
    p.add_argument('--json', type=Path, help='write the comparison as JSON')
    p.add_argument('--png', type=Path, help='write the figure: tracking against noise, and '
                   "one run's pointing error in the azimuth-elevation plane")
    return p


def ekf_config(args: argparse.Namespace) -> ConicalEKFConfig:
    """Return the conical-scan EKF the arguments set (scan circle, wide prior, smoother)."""
    return ConicalEKFConfig(dim_radius=args.dim_radius, dim_peak=args.dim_peak, wide=args.wide,
                            smooth_after=args.smooth_after, smooth_every=args.smooth_every)


def config_record(args: argparse.Namespace) -> dict[str, Any]:
    """Return the JSON's config: the settings and the definitions of the numbers."""
    return {'axes': 2, 'runs': args.runs, 'beta_deg_per_s': args.beta, 'steps': args.steps,
            'dt_s': args.dt, 'seed': args.seed, 'dropout': args.dropout,
            'jitter_s': args.jitter,
            'offset0_deg': args.offset0, 'cold_start_deg': args.cold_start,
            'clip_four_point': args.clip_four_point, 'max_intensity_v': led.MAX_INTENSITY,
            'dim_radius_deg': args.dim_radius, 'dim_peak_v': args.dim_peak,
            'wide_deg': args.wide, 'smooth_after': args.smooth_after,
            'smooth_every': args.smooth_every,
            'methods': {name: METHODS[name] for name in args.methods},
            'tracking': {'angle_deg': led.TRACKING_ANGLE,
                         'level_v': led.TRACKING_LEVEL * led.MAX_INTENSITY},
            'intervals': f'95 %: percentile bootstrap over runs ({RESAMPLES} resamples) for '
                         'means, Wilson for proportions',
            'rms_error_deg': 'RMS over a run of the mean pointing error: azimuth as the '
                             'cross-elevation angle wrap(a - a_s) cos e_s, elevation e - e_s'}


def progress(line: str) -> None:
    """Say how the run goes, on stderr."""
    print(f'[alignment_mc] {line}', file=sys.stderr, flush=True)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the two-axis comparison; return the exit status."""
    args = parser().parse_args(argv)
    if args.methods is None:
        args.methods = default_methods()
    args.methods = list(dict.fromkeys(args.methods))      # a method named twice runs once
    unknown = [name for name in args.methods if name not in METHODS]
    if unknown or not args.methods:
        parser().error(f'--methods: unknown {unknown} (known: {", ".join(METHODS)})')
    missing = [name for name in args.methods if not available(name)]
    if missing:
        parser().error(f'--methods: {", ".join(missing)} cannot be built in this version')
    for option, path in (('--json', args.json), ('--png', args.png)):
        why = output.unwritable(path) if path is not None else None
        if why:
            parser().error(f'{option} {path}: {why}')

    try:
        response = RadialResponse()
        link = PanTiltLinkConfig(beta=args.beta, dt=args.dt, steps=args.steps,
                                 dropout=args.dropout, jitter=args.jitter,
                                 offset0=args.offset0, cone=args.cold_start)
    except led.AlignmentError as exc:
        print(f'alignment_mc: {exc}', file=sys.stderr)
        return 2
    progress(f'two axes: beta {args.beta:g} deg/s per axis; {args.steps} steps of {args.dt:g} '
             f's; {args.runs} runs per point; methods {", ".join(args.methods)}')
    try:
        out = sweep(args.noise_levels, args.methods, runs=args.runs, link=link, seed=args.seed,
                    response=response, clip=args.clip_four_point, progress=progress,
                    workers=args.workers, scheduler=args.scheduler,
                    ekf=ekf_config(args))
    except monte_carlo.SchedulerError as exc:
        print(f'alignment_mc: {exc}', file=sys.stderr)
        return 1
    progress(f'comparison done in {out["elapsed_s"]:.1f} s')
    print(table(args.noise_levels, out['results']))
    data = {'noise_levels': list(args.noise_levels), 'results': out['results'],
            'config': config_record(args), 'elapsed_s': out['elapsed_s']}
    try:
        write_outputs(args, data, out['results'], link, response)
    except OSError as exc:
        # checked before the run; a disk that filled or a folder that went meanwhile
        print(f'alignment_mc: cannot write the output: {exc}', file=sys.stderr)
        return 1
    return 0


def write_outputs(args: argparse.Namespace, data: dict, results: dict,
                  link: PanTiltLinkConfig, response: RadialResponse) -> None:
    """Write the JSON and the figure that the arguments ask for, each whole or not at all."""
    if args.json:
        output.write_json(args.json, data)
        progress(f'wrote {args.json}')
    if args.png:
        run_link = dataclasses.replace(link, noise=args.run_noise)
        ekf = ekf_config(args)
        runs = {name: simulate(Point(name, 1, run_link, args.seed, response,
                                     args.clip_four_point, ekf))[0] for name in args.methods}
        start = (f'cold start in a {args.cold_start:g} deg cone' if args.cold_start
                 else f'start {args.offset0:g} deg off')
        fig = plot_two_axis(args.noise_levels, results, runs, title=(
            f'Two axes: beta = {args.beta:g} deg/s per axis, {start}, {args.runs} runs, '
            f'seed {args.seed}'), run_title=f'one run (seed {args.seed}), noise '
                                            f'{args.run_noise:g} V',
                            acquisition=bool(args.cold_start))
        output.save_figure(fig, args.png, dpi=120)
        progress(f'wrote {args.png}')


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
