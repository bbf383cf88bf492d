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
"""The ablation's statistics (bootstrap over runs, Wilson), its tables and its figure."""

import math
from pathlib import Path
from typing import Any, Sequence, TYPE_CHECKING

import numpy as np

from tskf_ros.experiments import output

if TYPE_CHECKING:
    from matplotlib.figure import Figure

Z95 = 1.959963984540054              # the 0.975 quantile of N(0, 1)
TABLE_LEVELS = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)      # V: the levels the markdown shows


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """
    Wilson's score interval of a binomial proportion k / n (Wilson, JASA 1927).

    (p + z^2/2n +- z sqrt(p(1 - p)/n + z^2/4n^2)) / (1 + z^2/n), p = k / n.
    """
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def bootstrap_ci(values: np.ndarray, index: np.ndarray) -> tuple[float, float]:
    """Return the 95 % percentile bootstrap interval of the mean; index: (resamples, runs)."""
    means = values[index].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


def summarise(rows: Sequence[Any], levels: Sequence[float], per_run: dict, *,
              rng: np.random.Generator, resamples: int) -> dict:
    """
    Return the JSON record: per row and level the mean and 95 % interval of each measure.

    per_run[row][level] holds the per-run arrays of run_cell.  One set of bootstrap
    indices serves every cell, so the gain of a row over its parent is a paired
    bootstrap over the same runs (common random numbers).
    """
    runs = len(next(iter(per_run.values()))[0]['angular'])
    index = rng.integers(0, runs, size=(resamples, runs))
    results: dict = {}
    for row in rows:
        cells = per_run[row.name]
        entry: dict = {'label': row.label, 'parent': row.parent,
                       'angular_pct': {'mean': [], 'ci95': []},
                       'mean_abs_phi_deg': {'mean': [], 'ci95': []},
                       'lost_at_end': {'fraction': [], 'count': [], 'ci95': []},
                       'gain_over_parent_pct': {'mean': [], 'ci95': [], 'significant': []}}
        for i, cell in enumerate(cells):
            for key, values in (('angular_pct', cell['angular']),
                                ('mean_abs_phi_deg', cell['mean_abs_phi'])):
                entry[key]['mean'].append(float(np.mean(values)))
                entry[key]['ci95'].append(bootstrap_ci(values, index))
            k = int(np.count_nonzero(cell['lost']))
            entry['lost_at_end']['fraction'].append(k / runs)
            entry['lost_at_end']['count'].append(k)
            entry['lost_at_end']['ci95'].append(wilson(k, runs))
            gain = entry['gain_over_parent_pct']
            if row.parent is None or row.parent not in per_run:
                for key in gain:
                    gain[key].append(None)
                continue
            diff = cell['angular'] - per_run[row.parent][i]['angular']
            lo, hi = bootstrap_ci(diff, index)
            gain['mean'].append(float(np.mean(diff)))
            gain['ci95'].append((lo, hi))
            gain['significant'].append(bool(lo > 0.0 or hi < 0.0))
        results[row.name] = entry
    return {'noise_levels': [float(v) for v in levels], 'results': results,
            'method': {'interval': '95 % percentile bootstrap over runs (runs independent, '
                                   'the steps within a run correlated)',
                       'resamples': resamples,
                       'gain': 'paired: the same resampled runs for a row and its parent',
                       'lost_at_end': 'Wilson score interval, binomial over runs'}}


def _pct(mean: float, ci: Sequence[float]) -> str:
    return f'{mean:.2f} [{ci[0]:.2f}, {ci[1]:.2f}]'


def _signed(v: float) -> str:
    # two decimals, three where two would print a non-zero bound as 0.00
    return f'{v:+.3f}' if 0.0 < abs(v) < 0.005 else f'{v:+.2f}'


def _gain(mean: float, ci: Sequence[float], significant: bool) -> str:
    text = f'{_signed(mean)} [{_signed(ci[0])}, {_signed(ci[1])}]'
    return text if significant else text + ' n.s.'


def _columns(data: dict) -> list[int]:
    levels = data['noise_levels']
    picked = [i for i, v in enumerate(levels) if any(abs(v - t) < 1e-9 for t in TABLE_LEVELS)]
    return picked or list(range(len(levels)))


def markdown_tables(data: dict) -> str:
    """Return the markdown tables: tracking %, gain over the parent, lost at the end."""
    cols = _columns(data)
    levels = data['noise_levels']
    head = '| row | ' + ' | '.join(f'{levels[i]:g} V' for i in cols) + ' |'
    rule = '|---|' + '---|' * len(cols)
    res = data['results']
    out = ['Angular tracking % (mean over runs, 95 % bootstrap interval):', '', head, rule]
    for name, e in res.items():
        a = e['angular_pct']
        out.append(f'| {e["label"]} | ' + ' | '.join(_pct(a['mean'][i], a['ci95'][i])
                                                     for i in cols) + ' |')
    out += ['', 'Gain over the parent row, percentage points (paired bootstrap over the same '
            'runs; n.s.: the interval holds 0, no significant difference):', '',
            head.replace('| row |', '| row (parent) |'), rule]
    for name, e in res.items():
        g = e['gain_over_parent_pct']
        if e['parent'] is None or g['mean'][0] is None:
            continue
        out.append(f'| {e["label"]} ({res[e["parent"]]["label"]}) | ' + ' | '.join(
            _gain(g['mean'][i], g['ci95'][i], g['significant'][i]) for i in cols) + ' |')
    out += ['', 'Runs out of the cone at the last step (count of runs; Wilson 95 % interval of '
            'the fraction):', '', head, rule]
    for name, e in res.items():
        lost = e['lost_at_end']
        out.append(f'| {e["label"]} | ' + ' | '.join(
            f'{lost["count"][i]} [{lost["ci95"][i][0]:.3f}, {lost["ci95"][i][1]:.3f}]'
            for i in cols) + ' |')
    out += ['', 'Mean |phi| (deg, 95 % bootstrap interval):', '', head, rule]
    for name, e in res.items():
        m = e['mean_abs_phi_deg']
        out.append(f'| {e["label"]} | ' + ' | '.join(_pct(m['mean'][i], m['ci95'][i])
                                                     for i in cols) + ' |')
    return '\n'.join(out) + '\n'


def write_markdown(path: Path, data: dict, *, command: str) -> None:
    """Write the tables as a page of the docs, with the command that made them."""
    cfg = data['config']
    text = '\n'.join([
        '# Pointing ablation: what each ingredient adds', '',
        'Generated by the command below (do not edit by hand). Each row adds one '
        'ingredient to its parent row, on the same runs (common random numbers, seed '
        f'{cfg["seed"]}): the prior (the P0 = diag(100, 1000) of Table I clipped to '
        'diag(4, 25)), the noise (the R = 1 V^2 of Table I replaced by R = sigma^2 of the link, '
        f'sigma at least {cfg["min_noise_v"]:g} V), the supervisor (hold, search, '
        're-acquire, from a known start) and the LQG controller (given the same prior '
        f'and R, drift variance {cfg["lqg_b_var"]:g}). The supervisor cannot steer the '
        f'LQG. {cfg["runs"]} runs per cell, beta = {cfg["beta_deg_per_s"]:g} deg/s, '
        f'{cfg["steps"]} steps of {cfg["dt_s"] * 1000:g} ms, x2_0 = {cfg["x2_0_deg"]:g} deg. '
        f'{data["method"]["interval"]}, {data["method"]["resamples"]} resamples; the '
        'gains are paired over the same runs. The JSON (`ablation.json`) has all '
        f'{len(data["noise_levels"])} noise levels; the tables show {len(_columns(data))}.',
        '',
        '```', command, '```', '',
        markdown_tables(data), '![tracking against noise, each ingredient](ablation.png)', ''])
    output.write_text(path, text)


def text_table(data: dict) -> str:
    """Return a plain-text table of the mean tracking % per row and level."""
    levels = data['noise_levels']
    lines = [f'{"row":>40} | ' + ' '.join(f'{v:>7.2f}' for v in levels)]
    for e in data['results'].values():
        lines.append(f'{e["label"]:>40} | ' + ' '.join(f'{m:7.2f}'
                                                       for m in e['angular_pct']['mean']))
    return '\n'.join(lines)


def plot(data: dict) -> 'Figure':
    """Tracking % against noise with 95 % intervals: the EKF's ingredients, the baselines."""
    from matplotlib.figure import Figure  # here: 0.7 s to import
    fig = Figure(figsize=(11.0, 4.8))
    axes = fig.subplots(1, 2, sharey=True)
    levels = np.asarray(data['noise_levels'])
    res = data['results']
    groups = (('the EKF, one ingredient at a time',
               [n for n in res if n.startswith(('ekf', 'lqg'))]),
              ('the baselines, with and without the supervisor',
               [n for n in res if not n.startswith(('ekf', 'lqg'))]
               + [n for n in ('ekf+prior+R+sup',) if n in res]))
    for ax, (title, names) in zip(axes, groups):
        for j, name in enumerate(names):
            e = res[name]['angular_pct']
            mean = np.asarray(e['mean'])
            ci = np.asarray(e['ci95'], dtype=float).reshape(-1, 2)
            err = np.abs(np.stack([mean - ci[:, 0], ci[:, 1] - mean]))
            ax.errorbar(levels + 0.012 * (j - len(names) / 2), mean, yerr=err, fmt='-o',
                        ms=3, capsize=2, lw=1.1, label=res[name]['label'])
        ax.set_xlabel('noise level (std of v, V)')
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7.5, loc='lower left')
    axes[0].set_ylabel('angular tracking (%), 95 % interval')
    fig.suptitle(f'Pointing ablation: {data["config"]["runs"]} runs per point, '
                 f'beta = {data["config"]["beta_deg_per_s"]:g} deg/s, seed '
                 f'{data["config"]["seed"]}', fontsize=11)
    fig.tight_layout()
    return fig


def write_json(path: Path, data: dict) -> None:
    """Write the record as JSON, atomically."""
    output.write_json(path, data)


def save_figure(fig: 'Figure', path: Path) -> None:
    """Save the figure as PNG, atomically."""
    output.save_figure(fig, path, dpi=120)


__all__ = ['bootstrap_ci', 'markdown_tables', 'plot', 'save_figure', 'summarise',
           'text_table', 'wilson', 'write_json', 'write_markdown']
