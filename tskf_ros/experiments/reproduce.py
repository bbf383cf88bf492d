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

"""Reproduce the papers' numerical examples: B&W Example 3.20 and Cai et al. Section V."""

import argparse
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Optional

import numpy as np

from tskf_ros.core import linear_models as models, time_scales as timescale
from tskf_ros.experiments import arguments
from tskf_ros.experiments.output import save_figure, write_json

# the command line's most points per time scale, and its finest dense step (P_1,2, T_d)
MAX_POINTS = 100_000
MIN_STEP = 0.001


@dataclass
class Series:
    """One run, ready for metrics and plots (first state / the measured quantity)."""

    name: str
    t: np.ndarray
    mu: np.ndarray
    truth: np.ndarray
    measured: np.ndarray     # the measurement in state units
    pred: np.ndarray
    corr: np.ndarray         # NaN at the last point
    sd_pred: np.ndarray      # sqrt of P_pred[0, 0]
    unit: str


def rms(e: np.ndarray) -> float:
    """Root mean square over the finite entries."""
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e ** 2))) if e.size else float('nan')


def metrics(s: Series) -> dict:
    """RMS and max errors of the predictor, the corrected estimate and the measurement."""
    ep, ec, em = s.pred - s.truth, s.corr - s.truth, s.measured - s.truth
    return {
        'points': int(s.t.size),
        'rms_estimation_error': rms(ep),
        'rms_corrected_error': rms(ec),
        'rms_measurement_error': rms(em),
        'max_abs_estimation_error': float(np.max(np.abs(ep))),
        'max_abs_corrected_error': float(np.nanmax(np.abs(ec))),
    }


def crowded_stretch(t: np.ndarray) -> Optional[tuple]:
    """
    Return (t_a, t_b) if most points lie in a small part of the time range, else None.

    The tail of points within 5% of the range before the last one holds more than half of
    them (Example 3.20's 2Z then H_n: 145 of 150 points after t = 8).
    """
    span = t[-1] - t[0]
    if t.size < 20 or span <= 0:
        return None
    k = int(np.searchsorted(t, t[-1] - 0.05 * span))
    return (float(t[k]), float(t[-1])) if t.size - k > t.size // 2 else None


def _mark_jumps(b, x: np.ndarray, err: np.ndarray, s: Series, marks: list) -> None:
    """Label each jump's point J=..., staggered upwards where labels would overlap."""
    width = (x.max() - x.min()) or 1.0
    last, level = -np.inf, 0
    for tm, label in sorted(marks):
        k = int(np.argmin(np.abs(s.t - tm)))
        level = level + 1 if x[k] - last < 0.06 * width else 0
        last = x[k]
        b.annotate(label, (x[k], err[k]), textcoords='offset points',
                   xytext=(0, 6 + 9 * level), ha='center', fontsize=7, color='tab:red')


def plot_series(s: Series, title: str, marks: Optional[list] = None):
    """
    Cai Fig. 2 style: left 'plot in iteration', right 'plot in time scale'.

    A third column zooms on the stretch where most points crowd (crowded_stretch).  The
    top row's axis spans the true state and both estimates; measurements beyond it are
    drawn on its edge as triangles.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    zoom = crowded_stretch(s.t)
    columns = [(np.arange(s.t.size), 'iteration', 'plot in iteration'),
               (s.t, 'time t on the time scale', 'plot in time scale')]
    if zoom:
        columns.append((s.t, 'time t on the time scale',
                        f'time scale from t = {zoom[0]:.4g} to {zoom[1]:.4g}'))
    fig, ax = plt.subplots(2, len(columns), figsize=(6 * len(columns), 6.5), sharex='col',
                           squeeze=False)
    stacked = np.r_[s.truth, s.pred, s.corr]
    lo, hi = np.nanmin(stacked), np.nanmax(stacked)
    pad = 0.08 * (hi - lo + 1e-9)
    lo, hi = lo - pad, hi + pad
    errors = [(np.abs(s.measured - s.truth), '0.6', '|measurement error|'),
              (np.abs(s.pred - s.truth), 'tab:red', '|estimation error|'),
              (np.abs(s.corr - s.truth), 'tab:blue', '|corrected error|')]
    for col, (x, xlabel, heading) in enumerate(columns):
        style = {'marker': '.', 'ms': 3}
        style.update({'lw': 0.8} if col == 0 else {'ls': 'none'})
        a = ax[0, col]
        a.plot(x, np.clip(s.measured, lo, hi), color='0.6', label='measurement', **style)
        off = (s.measured > hi) | (s.measured < lo)
        if off.any():
            a.plot(x[off], np.where(s.measured[off] > hi, hi, lo), ls='none', marker='^',
                   ms=4, color='0.6', label='measurement beyond the axis')
        a.plot(x, s.truth, color='k', label='true', **style)
        a.plot(x, s.pred, color='tab:red', label='estimate (Table 3 predictor)', **style)
        a.plot(x, s.corr, color='tab:blue', label='corrected estimate', **style)
        a.set_ylim(lo, hi)
        a.set_ylabel(s.unit)
        a.set_title(heading)
        b = ax[1, col]
        for err, color, label in errors:
            b.plot(x, err, color=color, label=label, **style)
        b.set_yscale('log')
        b.set_xlabel(xlabel)
        b.set_ylabel(f'|error| ({s.unit})')
        _mark_jumps(b, x, errors[1][0], s, marks or [])
        if zoom and col == 2:
            for axis in (a, b):
                axis.set_xlim(zoom[0] - 0.02 * (zoom[1] - zoom[0]),
                              zoom[1] + 0.02 * (zoom[1] - zoom[0]))
    top = max(np.nanmax(e) for e, _, _ in errors)
    for b in ax[1]:
        b.set_ylim(top=top * 30)     # room for the J labels above the largest error
    for row in ax:                   # the legends beside the panels, over no data
        row[-1].legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title)
    fig.tight_layout()
    return fig


EXAMPLE_320_SCALES = ('2Z', 'H_n', 'P_1,2', '2Z_then_H_n')


def example_320_timescale(name: str, count: int, p12_step: float) -> timescale.TimeScale:
    """Build one of the four time scales of Example 3.20 / Cai Fig. 2, count points."""
    if name == '2Z':
        return timescale.h_integers(2.0, count)
    if name == 'H_n':
        # from H_1: mu(H_0) = 1 and I + A is singular for this A (not regressive on Z)
        return timescale.harmonic(count, first=1)
    if name == 'P_1,2':
        per_period = int(round(1.0 / p12_step)) + 1
        return timescale.p_ab(1.0, 2.0, count // per_period + 2, p12_step).head(count)
    if name == '2Z_then_H_n':
        return timescale.cai_t3(count)
    raise ValueError(f'unknown time scale {name!r}')


def run_example_320(name: str, count: int, rng: np.random.Generator, *,
                    noise_scaling: str, p12_step: float) -> Series:
    """Simulate the spring-mass system on a time scale and run the filter."""
    model = models.spring_mass()
    ts = example_320_timescale(name, count, p12_step)
    x, y = models.simulate_truth(model, ts, rng, noise_scaling=noise_scaling)
    run = models.run_filter(model, ts, y)
    return Series(name, ts.points, ts.mu(), x[:, 0], y[:, 0], run.x_pred[:, 0],
                  run.x_corr[:, 0], np.sqrt(run.P_pred[:, 0, 0]), 'position (ft)')


def post_jump_report(s: Series, jumps: list) -> list:
    """Errors at the points right after each jump."""
    out = []
    for t_after, J in jumps:
        k = int(np.argmin(np.abs(s.t - t_after)))
        out.append({'t': float(s.t[k]), 'J': float(J),
                    'estimation_error': float(s.pred[k] - s.truth[k]),
                    'corrected_error': float(s.corr[k] - s.truth[k]),
                    'measurement_error': float(s.measured[k] - s.truth[k])})
    return out


def worst_points(s: Series, count: int = 5) -> list:
    """Return the count largest |estimation errors|, with the graininess before each."""
    e = np.abs(s.pred - s.truth)
    nu = timescale.backward_graininess(s.t)
    idx = np.argsort(e)[::-1][:count]
    return [{'t': float(s.t[k]), 'abs_estimation_error': float(e[k]),
             'mu_before': float(nu[k])} for k in idx]


def run_cai_td(system: str, td: timescale.TimeScale, rng: np.random.Generator, *,
               noise_scaling: str) -> dict:
    """Cai Section V on T_d: returns {'euler': Series, 'exact': Series}."""
    mu = td.mu()
    mu_meas = np.where(mu > 0, mu, np.r_[mu[:-1], mu[-2]][-1])
    vscale = 1.0 / np.sqrt(mu_meas) if noise_scaling == 'theory' else np.ones(mu.size)
    if system == 'reference':
        model = models.spring_mass()
        x, y = models.simulate_truth(model, td, rng, noise_scaling=noise_scaling)
        truth, meas_state, unit = x[:, 0], y[:, 0], 'position (ft)'
    else:
        model = models.owc(a=1.0 if system == 'owc' else 0.0)
        truth = models.ou_angle(td.points, rng)
        y = (models.OWC_SLOPE * truth + models.OWC_OFFSET
             + 10.0 * rng.standard_normal(truth.size) * vscale)[:, None]
        meas_state, unit = (y[:, 0] - models.OWC_OFFSET) / models.OWC_SLOPE, 'theta (rad)'
    out = {}
    for transition in ('euler', 'exact'):
        # System (1) has eigenvalue -1: at T_d's mu = 1 points I + A is singular.  Cai et al.
        # run it anyway; so do we, said here and in the README (Definition 2.12).
        run = models.run_filter(model, td, y, transition=transition,
                                allow_nonregressive=system == 'reference')
        out[transition] = Series(system, td.points, mu, truth, meas_state, run.x_pred[:, 0],
                                 run.x_corr[:, 0], np.sqrt(run.P_pred[:, 0, 0]), unit)
    return out


def td_summary(series: dict) -> dict:
    """Metrics, the five post-jump points and the worst points for each transition."""
    res = {}
    post = list(timescale.CAI_TD_JUMPS)
    for transition, s in series.items():
        m = metrics(s)
        pj = post_jump_report(s, post)
        mask = np.ones(s.t.size, bool)
        for p in pj:
            mask[np.argmin(np.abs(s.t - p['t']))] = False
        m['rms_estimation_error_without_post_jump_points'] = rms((s.pred - s.truth)[mask])
        m['rms_corrected_error_without_post_jump_points'] = rms((s.corr - s.truth)[mask])
        m['post_jump_points'] = pj
        m['worst_points'] = worst_points(s)
        pe = np.array([abs(p['estimation_error']) for p in pj])
        pc = np.array([abs(p['corrected_error']) for p in pj])
        m['post_jump_mean_abs_error'] = {'predictor': float(pe.mean()),
                                         'corrected': float(pc.mean()),
                                         'ratio_corrected_to_predictor':
                                             float(pc.mean() / pe.mean())}
        res[transition] = m
    return res


def parse_args(argv: Optional[list] = None) -> argparse.Namespace:
    """Parse and check the command line (one usage line for a value out of range)."""
    parser = argparse.ArgumentParser(
        prog='reproduce',
        description='Reproduce Bohner & Wintz Example 3.20 and Cai et al. Section V '
                    '(PNGs and JSON into --out).')
    parser.add_argument('--out', type=Path, default=Path('results'),
                        help='output folder (default: results/)')
    parser.add_argument('--seed', type=arguments.seed, default=2013, help='base random seed')
    parser.add_argument('--noise-scaling', choices=models.NOISE_SCALINGS, default='theory',
                        help="'theory': process noise mu*GQG^T per jump, measurement R/mu "
                             "(what Table 3 assumes); 'unit': N(0, Q) and N(0, R) at every "
                             'point whatever mu is')
    points = arguments.count(2, MAX_POINTS)
    parser.add_argument('--iterations', type=points, default=15,
                        help='points per time scale in the paper-length run (default 15)')
    parser.add_argument('--long-iterations', type=points, default=150,
                        help='points per time scale in the longer run (default 150)')
    step = arguments.number(MIN_STEP, 1.0)
    parser.add_argument('--p12-step', type=step, default=0.25,
                        help='step realising the dense parts of P_1,2, below 1 (default 0.25)')
    parser.add_argument('--td-dense-step', type=step, default=0.1,
                        help='step realising the dense parts of T_d in s (default 0.1)')
    args = parser.parse_args(argv)
    if args.p12_step == 1.0:
        # mu = 1 on P_1,2's dense part: I + mu A is singular for the spring-mass A
        parser.error('argument --p12-step: must be below 1 (at 1, A is not regressive on '
                     'P_1,2)')
    return args


def main(argv: Optional[list] = None) -> int:
    """Command-line entry point."""
    args = parse_args(argv)

    out = args.out
    summary: dict = {'seed': args.seed, 'noise_scaling': args.noise_scaling,
                     'example_3_20': {}, 'cai_td': {}}
    t_start = time.perf_counter()
    for i, name in enumerate(EXAMPLE_320_SCALES):
        for label, count in (('paper', args.iterations), ('long', args.long_iterations)):
            rng = np.random.default_rng([args.seed, i, count])
            s = run_example_320(name, count, rng, noise_scaling=args.noise_scaling,
                                p12_step=args.p12_step)
            m = metrics(s)
            fname = f"example_3_20_{name.replace(',', '').replace('_', '')}_{label}"
            save_figure(plot_series(s, f'B&W Example 3.20 on {name} ({count} points, '
                                       f'{args.noise_scaling} noise)'), out / f'{fname}.png')
            write_json(out / f'{fname}.json', m)
            summary['example_3_20'].setdefault(name, {})[label] = m
            print(f'[example 3.20] {name:12s} {count:4d} points: RMS estimation error '
                  f"{m['rms_estimation_error']:.3f}, corrected {m['rms_corrected_error']:.3f}, "
                  f"measurement {m['rms_measurement_error']:.3f} -> {fname}.png", flush=True)

    td = timescale.cai_td(args.td_dense_step)
    marks = [(t, f'J={J:g}') for t, J in timescale.CAI_TD_JUMPS]
    for i, system in enumerate(('owc', 'owc_random_walk', 'reference')):
        rng = np.random.default_rng([args.seed, 100 + i])
        series = run_cai_td(system, td, rng, noise_scaling=args.noise_scaling)
        res = td_summary(series)
        summary['cai_td'][system] = res
        write_json(out / f'cai_td_{system}.json', res)
        title = f'Cai T_d, {system} (I + mu A), {args.noise_scaling} noise'
        save_figure(plot_series(series['euler'], title, marks), out / f'cai_td_{system}.png')
        e = res['euler']
        pj = ', '.join(f"t={p['t']:g} J={p['J']:g}: {p['estimation_error']:+.3f}/"
                       f"{p['corrected_error']:+.3f}" for p in e['post_jump_points'])
        print(f'[cai T_d] {system}: RMS estimation error {e["rms_estimation_error"]:.4f} '
              f'(exact transition {res["exact"]["rms_estimation_error"]:.4f}), corrected '
              f'{e["rms_corrected_error"]:.4f}; post-jump predictor/corrected errors: {pj}; '
              f'worst at t = {[w["t"] for w in e["worst_points"]]} -> cai_td_{system}.png',
              flush=True)
    summary['seconds'] = time.perf_counter() - t_start
    write_json(out / 'summary.json', summary)
    print(f'wrote {out}/summary.json and the PNGs in {summary["seconds"]:.1f} s')
    return 0


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
