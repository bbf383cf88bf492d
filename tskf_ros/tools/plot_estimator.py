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
plot_bag's estimator figure (Cai et al. Fig. 2's two styles), from rows streamed off a bag.

An estimate is read as its t, x_0, P_00 and mu; a measurement as its t and y; the truth as
its t and angle (plot_rows.stream).  The errors' RMS are taken over every point; a series
longer than plot_rows.DRAWN points is drawn as its envelope.
"""

from typing import Any, Callable

from matplotlib.figure import Figure
import matplotlib.pyplot as plt
import numpy as np

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.tools.plot_rows import band, drawn_note, envelope, RowKind


def _estimate(msg: Any) -> tuple:
    """Return an estimate message's row: (t s, x_0, P_00, mu s)."""
    e = conversions.msg_to_state_estimate(msg)
    return e.stamp_ns / NS, float(e.x[0]), float(e.P[0, 0]), float(e.mu)


def _power(msg: Any) -> tuple:
    """Return an Illuminance measurement's row: (t s, y)."""
    stamp, y, _ = conversions.msg_to_power(msg)
    return stamp / NS, y


def _truth(msg: Any) -> tuple:
    """Return a true-angle JointState's row: (t s, its first position, rad)."""
    return conversions.stamp_to_ns(msg.header.stamp) / NS, float(msg.position[0])


ESTIMATE = RowKind(_estimate, 4)      # (t s, x_0, P_00, mu s)
POWER = RowKind(_power, 2)            # (t s, y)
TRUTH = RowKind(_truth, 2)            # (t s, the true angle, rad)


def estimator_figure(series: dict[str, np.ndarray], measurement: np.ndarray,
                     truth: np.ndarray, C: float, D: float, title: str) -> Figure:
    """
    Draw an estimator run in iteration and in time scale; return the figure.

    series: {'predictor' | 'corrected' | 'smoothed': (N, 4) rows of ESTIMATE}, the
    first two required; measurement (N, 2) of POWER; truth (N, 2) of TRUTH.
    """
    tp, xp, vp, mu_p = series['predictor'].T
    tc = series['corrected'][:, 0]
    # mu_k of each step t_k -> t_{k+1}: carried by the prediction into t_{k+1}
    steps = mu_p > 0
    tm, mu = tp[steps] - mu_p[steps], mu_p[steps]
    styles = {'predictor': ('C0', 'predictor xhat(t)'), 'corrected': ('C3', 'corrected x(t|t)'),
              'smoothed': ('C4', 'smoothed x(t|T)')}
    shown_series = [(series[k][:, 0], series[k][:, 1], series[k][:, 2], *styles[k], k)
                    for k in ('predictor', 'corrected', 'smoothed') if k in series]
    ty, y = measurement[:, 0], measurement[:, 1]
    t_true, x_true = truth[:, 0], truth[:, 1]
    t0 = min(tp.min(), ty.min()) if ty.size else tp.min()
    fig, axes = plt.subplots(4, 2, figsize=(14, 12.5), sharex='col')
    beside = {'fontsize': 7, 'loc': 'upper left', 'bbox_to_anchor': (1.01, 1.0)}
    for col, style in enumerate(('iteration', 'time scale')):
        def pos(t: np.ndarray, stamps: np.ndarray = tc) -> np.ndarray:
            if style == 'time scale':
                return t - t0
            return np.searchsorted(stamps, t, side='left')
        # the estimates after the measurement (top), the predictor (its band spans
        # radians after a gap) in a panel of its own, so that neither squeezes the other
        for row, shown in ((0, shown_series[1:]), (1, shown_series[:1])):
            ax = axes[row, col]
            if t_true.size:
                keep = (t_true >= tc.min()) & (t_true <= tc.max()) if style == 'iteration' \
                    else np.ones(t_true.size, bool)
                ax.plot(*_at(pos, *envelope(t_true[keep], x_true[keep])), 'k-', lw=1,
                        label='true angle')
            if row == 0:    # on top of every line and band: none hides them
                ax.plot(*_at(pos, *envelope(ty, (y - D) / C)), 'o', color='0.3', ms=2.5,
                        zorder=5, label='implied by measurement (y - D) / C')
            for t, x, v, color, name, _ in shown:
                tb, lo, hi = band(t, x, 2 * np.sqrt(np.maximum(v, 0)))
                ax.fill_between(pos(tb), lo, hi, color=color, alpha=0.2,
                                label=f'{name} +-2 sigma')
                ax.plot(*_at(pos, *envelope(t, x)), '-', color=color, lw=1, label=name)
            # the estimates and the truth in full (none runs off the axis); the band may
            top = np.concatenate([x for _, x, _, _, _, _ in shown] + [x_true])
            lo_y, hi_y = np.nanmin(top), np.nanmax(top)
            pad = max(0.1 * (hi_y - lo_y), 1e-3)
            ax.set_ylim(lo_y - pad, hi_y + pad)
            ax.set_ylabel('angle (rad)')
            if col == 1:    # beside the panels, over no data
                ax.legend(**beside)
        axes[0, col].set_title(f'plot in {style}')
        ax = axes[2, col]
        if t_true.size:
            for t, x, v, color, _, name in shown_series:
                err = x - np.interp(t, t_true, x_true)
                ax.plot(*_at(pos, *envelope(t, err)), '.-', color=color, lw=0.6, ms=2,
                        label=f'{name}: RMS {np.sqrt(np.mean(err ** 2)):.3g} rad')
            if col == 1:
                ax.legend(**beside)
        else:
            ax.text(0.5, 0.5, 'no true angle in the bag', ha='center',
                    transform=ax.transAxes)
        ax.set_ylabel('estimation error (rad)')
        ax = axes[3, col]
        ax.step(*_at(pos, *envelope(tm, mu)), where='post', color='C2',
                label='mu: the time to the next point')
        if col == 1:
            ax.legend(**beside)
        ax.set_ylabel('mu (s)')
        ax.set_xlabel('iteration k' if style == 'iteration' else 'time t - t0 (s)')
    title += drawn_note(max(len(tp), len(ty)))
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _at(pos: Callable[[np.ndarray], np.ndarray], t: np.ndarray, *ys: np.ndarray) -> tuple:
    """Return (pos(t), y...): the drawn points at their place on the axis."""
    return (pos(t),) + ys
