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
"""The figures of alignment_mc: Fig. 10 (tracking against noise), Fig. 8/9 (one run)."""

from typing import Sequence, TYPE_CHECKING

import numpy as np

from tskf_ros import led

if TYPE_CHECKING:
    from matplotlib.figure import Figure

LABELS = {'ekf': 'EKF', 'hill_climbing': 'Hill', 'three_point': '3Point',
          'ekf_hold': 'EKF, last value held', 'ekf_pat': r'EKF+PAT ($R = \sigma^2$)',
          'ekf_reset': 'EKF reset',
          'hill_climbing_pat': 'Hill+PAT', 'three_point_pat': '3Point+PAT'}
COLORS = {'ekf': 'tab:blue', 'hill_climbing': 'tab:orange', 'three_point': 'tab:green',
          'ekf_hold': 'tab:purple', 'ekf_pat': 'navy', 'ekf_reset': 'tab:cyan',
          'hill_climbing_pat': 'saddlebrown', 'three_point_pat': 'darkgreen'}


def plot_tracking(x: Sequence[float], results: dict, *, xlabel: str, title: str,
                  std_scale: float = 5.0) -> 'Figure':
    """Fig. 10 style: mean tracking % with error bars of std / std_scale, both metrics."""
    from matplotlib.figure import Figure  # here: 0.7 s to import
    fig = Figure(figsize=(7.5, 4.8))
    ax = fig.add_subplot()
    for name, res in results.items():
        for metric, style in (('angular', '-o'), ('measure', '--s')):
            mean = np.asarray(res[metric]['mean'])
            std = np.asarray(res[metric]['std']) / std_scale
            ax.errorbar(x, mean, yerr=std, fmt=style, ms=3.5, capsize=2, lw=1.2,
                        color=COLORS.get(name), label=f'{LABELS.get(name, name)}-{metric}')
    ax.set_xlabel(xlabel)
    ax.set_ylabel('tracking percentage (%)')
    ax.set_ylim(0, 102)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, ncol=2, loc='lower left')
    fig.tight_layout()
    return fig


def plot_run(traj: led.Trajectory, *, title: str, threshold: float) -> 'Figure':
    """Fig. 8/9 style: x1 and x1hat, x2 and x2hat (with phi), measured and clean intensity."""
    from matplotlib.figure import Figure  # here: 0.7 s to import
    fig = Figure(figsize=(7.5, 7.0))
    axes = fig.subplots(3, 1, sharex=True)
    t = traj.t
    axes[0].plot(t, traj.x1[:, 0], 'k', lw=1.2, label='$x_1$')
    axes[0].plot(t, traj.estimate[:, 0, 0], 'tab:blue', lw=1.0, label=r'$\hat{x}_1$')
    axes[0].set_ylabel('$x_1$ (V)')
    axes[1].plot(t, traj.phi[:, 0], color='0.7', lw=0.8, label=r'$\phi = x_2 + \psi$')
    axes[1].plot(t, traj.x2[:, 0], 'k', lw=1.2, label='$x_2$')
    axes[1].plot(t, traj.estimate[:, 0, 1], 'tab:blue', lw=1.0, label=r'$\hat{x}_2$')
    for s in (-led.TRACKING_ANGLE, led.TRACKING_ANGLE):
        axes[1].axhline(s, color='tab:red', ls=':', lw=0.8)
    axes[1].set_ylabel('angle (deg)')
    axes[2].plot(t, traj.z[:, 0], color='0.6', lw=0.7, label='measured')
    axes[2].plot(t, traj.clean[:, 0], 'k', lw=1.0, label='clean')
    axes[2].axhline(threshold, color='tab:red', ls=':', lw=0.8, label='20% of 3 V')
    axes[2].set_ylabel('intensity (V)')
    axes[2].set_xlabel('time (s)')
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc='upper right')
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


__all__ = ['COLORS', 'LABELS', 'plot_run', 'plot_tracking']
