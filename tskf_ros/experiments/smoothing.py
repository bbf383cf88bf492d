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
Smoothed vs filtered estimates on the sample bags: RMS against truth and figures.

Every sample bag with a truth topic is replayed (replay_offline --smooth's arrays): the
predicted xhat(t), the corrected x(t|t) and the RTS-smoothed x(t|T) (Rauch, Tung &
Striebel 1965; tskf_ros.core.smoother) are compared with the true state at the stamps
the truth has.  Run: python -m tskf_ros.experiments.smoothing [--out docs/smoothing].
"""

import argparse
from pathlib import Path
import sys
from typing import NamedTuple, Optional

import matplotlib
import numpy as np
from numpy.typing import NDArray

from tskf_ros.bag.replay.loop import replay_arrays
from tskf_ros.bag.replay.sinks import SMOOTHED_TOPIC
from tskf_ros.core.units import NS
from tskf_ros.experiments.bag_analysis import read_stream
from tskf_ros.experiments.output import save_figure
from tskf_ros.messages.estimator_interface import load_config

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402, I100, I202

__all__ = ['BAGS', 'compare', 'Comparison', 'main', 'SampleBag']

REPO = Path(__file__).resolve().parents[2]
KINDS = ('predicted', 'corrected', 'smoothed')


class SampleBag(NamedTuple):
    """A sample bag with a truth topic: its parameters and which truth joint is state 0."""

    name: str
    params: str
    truth_topic: str
    joint: str
    unit: str
    quantity: str


BAGS = (SampleBag('owc_cai_td_1hz', 'owc_estimator.yaml', '/true_angle', 'theta', 'rad',
                  'angle theta'),
        SampleBag('owc_ge_1khz', 'owc_estimator.yaml', '/true_angle', 'theta', 'rad',
                  'angle theta'),
        SampleBag('drogue', 'drogue_estimator.yaml', '/drogue/truth', 'displacement_m', 'm',
                  'displacement'))


class Series(NamedTuple):
    """One kind of estimate of state 0: stamps (s from the first sample), x, variance."""

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    var: NDArray[np.float64]
    rms: float          # against truth at the stamps the truth has
    points: int         # how many stamps that is


class Comparison(NamedTuple):
    """The three kinds of estimate of one bag beside its truth and its measurements."""

    bag: SampleBag
    series: dict[str, Series]
    truth_t: NDArray[np.float64]
    truth_x: NDArray[np.float64]
    samples_t: NDArray[np.float64]


def compare(bags_dir: Path, bag: SampleBag, config_dir: Path) -> Comparison:
    """Replay one bag with smoothing; return its estimates, truth and RMS errors."""
    config = load_config(config_dir / bag.params)
    arrays = replay_arrays(bags_dir / bag.name, config, smooth=True)
    truth = read_stream(bags_dir / bag.name, config.session).truth[bag.truth_topic][bag.joint]
    t0 = int(arrays['sample.stamp_ns'][0])
    stamps, values = truth.stamps, truth.values
    series = {}
    for kind in KINDS:
        name = SMOOTHED_TOPIC.lstrip('/') if kind == 'smoothed' else f'estimate/{kind}'
        t_ns, x, P = arrays[f'{name}.stamp_ns'], arrays[f'{name}.x'], arrays[f'{name}.P']
        # the truth at the same stamps (exactly: both are on the bag's sample grid)
        at = np.searchsorted(stamps, t_ns).clip(0, max(stamps.size - 1, 0))
        hit = stamps[at] == t_ns
        err = x[hit, 0] - values[at[hit]]
        rms = float(np.sqrt(np.mean(err ** 2))) if err.size else float('nan')
        series[kind] = Series((t_ns - t0) / NS, x[:, 0], P[:, 0, 0], rms, int(hit.sum()))
    # the smoothed estimate at the corrected estimates' stamps only (the same points)
    sm, corr = series['smoothed'], series['corrected']
    same = np.isin(sm.t, corr.t)
    truth_at = np.interp(sm.t[same], (stamps - t0) / NS, values)
    series['smoothed_at_corrected'] = Series(
        sm.t[same], sm.x[same], sm.var[same],
        float(np.sqrt(np.mean((sm.x[same] - truth_at) ** 2))) if same.any() else float('nan'),
        int(same.sum()))
    accepted = np.isin(arrays['sample.status'], ('accepted', 'inserted', 'reset'))
    return Comparison(bag, series, (stamps - t0) / NS, values,
                      (arrays['sample.stamp_ns'][accepted] - t0) / NS)


STYLE = {'predicted': ('C0', 'predictor xhat(t)'), 'corrected': ('C3', 'corrected x(t|t)'),
         'smoothed': ('C4', 'smoothed x(t|T)')}


def _panel(ax, c: Comparison, lo: float, hi: float, *, markers: bool) -> None:
    """Draw truth and the three estimates (smoothed +-2 sigma) over [lo, hi] s."""
    keep = (c.truth_t >= lo) & (c.truth_t <= hi)
    ax.plot(c.truth_t[keep], c.truth_x[keep], 'k-', lw=1.2, label=f'true {c.bag.quantity}')
    for kind in KINDS:
        s = c.series[kind]
        k = (s.t >= lo) & (s.t <= hi)
        color, label = STYLE[kind]
        style = 'o' if kind == 'corrected' and not markers else '.-' if markers else '-'
        ax.plot(s.t[k], s.x[k], style, color=color, lw=1, ms=4,
                label=f'{label}: RMS {s.rms:.3g} {c.bag.unit}')
        if kind == 'smoothed':
            sd = 2 * np.sqrt(np.maximum(s.var[k], 0))
            ax.fill_between(s.t[k], s.x[k] - sd, s.x[k] + sd, color=color, alpha=0.2,
                            label='smoothed +-2 sigma')
    for t in c.samples_t[(c.samples_t >= lo) & (c.samples_t <= hi)]:
        ax.axvline(t, color='0.85', lw=0.5, zorder=0)
    ax.set_xlim(lo, hi)


def cai_figure(c: Comparison):
    """Draw Cai's T_d around its jumps: truth, predicted, corrected, smoothed."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8), sharey=True)
    for ax, (lo, hi) in zip(axes, ((120.0, 142.0), (204.0, 232.0))):
        _panel(ax, c, lo, hi, markers=True)
        ax.set_xlabel('time t - t0 (s)')
        ax.set_title(f'{lo:.0f}-{hi:.0f} s (grey lines: the samples; gaps are the jumps)')
    axes[0].set_ylabel('angle theta (rad)')
    axes[0].set_ylim(0.2, 1.6)      # the predictor's largest excursions are cut
    axes[1].legend(fontsize=7, loc='upper right')
    fig.suptitle(f'{c.bag.name}: predicted, corrected and RTS-smoothed estimates around '
                 'the jumps of T_d')
    fig.tight_layout()
    return fig


def drogue_figure(c: Comparison):
    """Draw the drogue's displacement between its intermittent fixes, and the errors."""
    fig, (ax, ax_e) = plt.subplots(2, 1, figsize=(12, 7.5), sharex=True)
    hi = float(c.truth_t.max())
    _panel(ax, c, 0.0, hi, markers=False)
    ax.set_ylabel('displacement (m)')
    ax.set_title('grey lines: the position fixes (between them only the acceleration u)')
    ax.legend(fontsize=7, loc='best')
    for kind in KINDS:
        s = c.series[kind]
        truth = np.interp(s.t, c.truth_t, c.truth_x)
        color, label = STYLE[kind]
        ax_e.plot(s.t, s.x - truth, 'o' if kind == 'corrected' else '-', color=color,
                  lw=0.8, ms=4, label=label)
    ax_e.axhline(0, color='k', lw=0.5)
    ax_e.set_ylim(-30, 30)          # the predictor's start from x0 = 0 (to -265 m) is cut
    ax_e.set_ylabel('estimate - truth (m)')
    ax_e.set_xlabel('time t - t0 (s)')
    ax_e.legend(fontsize=7)
    fig.suptitle(f'{c.bag.name}: displacement between intermittent fixes, filtered and '
                 'RTS-smoothed')
    fig.tight_layout()
    return fig


def table(comparisons: list[Comparison]) -> str:
    """Return the markdown RMS table of every bag: predicted, corrected, smoothed."""
    kinds = KINDS + ('smoothed_at_corrected',)
    lines = ['| bag | state | predicted RMS | corrected RMS | smoothed RMS | smoothed RMS at '
             'the corrected stamps | points (pred / corr / smooth) |',
             '| --- | --- | --- | --- | --- | --- | --- |']
    for c in comparisons:
        s = c.series
        lines.append(f'| `{c.bag.name}` | {c.bag.quantity} ({c.bag.unit}) | '
                     + ' | '.join(f'{s[k].rms:.4g}' for k in kinds) + ' | '
                     + ' / '.join(str(s[k].points) for k in KINDS) + ' |')
    return '\n'.join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    """Write the figures and print the RMS table; return the exit status."""
    parser = argparse.ArgumentParser(prog='python -m tskf_ros.experiments.smoothing',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--bags', type=Path, default=REPO / 'bags', help='sample bags')
    parser.add_argument('--config', type=Path, default=REPO / 'config',
                        help='parameter files')
    parser.add_argument('--out', type=Path, default=REPO / 'docs' / 'smoothing',
                        help='where the PNGs go')
    parser.add_argument('--only', choices=[b.name for b in BAGS], action='append',
                        help='only this bag (repeatable)')
    args = parser.parse_args(argv)
    chosen = [b for b in BAGS if not args.only or b.name in args.only]
    missing = [b.name for b in chosen if not (args.bags / b.name).is_dir()]
    if missing:
        print(f'smoothing: error: no bag {", ".join(missing)} in {args.bags}',
              file=sys.stderr)
        return 1
    comparisons = [compare(args.bags, b, args.config) for b in chosen]
    args.out.mkdir(parents=True, exist_ok=True)
    for c in comparisons:
        draw = {'owc_cai_td_1hz': cai_figure, 'drogue': drogue_figure}.get(c.bag.name)
        if draw is not None:
            fig = draw(c)
            path = save_figure(fig, args.out / f'{c.bag.name}_smoothed.png')
            plt.close(fig)
            print(f'wrote {path}')
    print(table(comparisons))
    return 0


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
