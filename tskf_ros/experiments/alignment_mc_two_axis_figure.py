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

"""The figure of `alignment_mc --axes 2`: tracking against noise, one run on the sky."""

from typing import Mapping, Sequence, TYPE_CHECKING

import numpy as np

from tskf_ros import led
from tskf_ros.led.two_axis.pan_tilt_simulation import PanTiltTrajectory

if TYPE_CHECKING:
    from matplotlib.figure import Figure

LABELS = {'conical_ekf': 'conical-scan EKF (P)',
          'conical_ekf_pat': 'conical-scan EKF + supervisor',
          'conical_lqg': 'conical-scan EKF, LQG', 'hill_climbing': 'hill climbing',
          'four_point': 'four-point'}
COLORS = {'conical_ekf': 'tab:blue', 'conical_ekf_pat': 'navy', 'conical_lqg': 'tab:purple',
          'hill_climbing': 'tab:orange', 'four_point': 'tab:green'}
ZOOM = 5.0          # deg: the half-width of the inset around the LED


def plot_two_axis(noise_levels: Sequence[float], results: dict,
                  runs: Mapping[str, PanTiltTrajectory], *, title: str,
                  run_title: str, acquisition: bool = False) -> 'Figure':
    """
    Left: tracking % by angle against noise, 95 % intervals as error bars; right: one run.

    acquisition (a cold start): the left panel is the % of runs acquired within 10 s
    instead, with their Wilson intervals.  The run is the error of the mean pointing in
    the tangent plane at the source (azimuth on the sky, elevation) of run 0 of each
    trajectory, with the 15 deg tracking cone.
    """
    from matplotlib.figure import Figure  # here: 0.7 s to import
    fig = Figure(figsize=(12.0, 5.2))
    left, right = fig.subplots(1, 2, gridspec_kw={'width_ratios': [1.25, 1.0]})
    x = np.asarray(noise_levels, dtype=float)
    for name, res in results.items():
        if acquisition:
            mean = 100.0 * np.asarray(res['acquired_within_10s'], dtype=float)
            ci = 100.0 * np.asarray(res['acquired_within_10s_ci95'], dtype=float).reshape(-1, 2)
        else:
            mean = np.asarray(res['angular']['mean'])
            ci = np.asarray(res['angular']['ci95'], dtype=float).reshape(-1, 2)
        yerr = np.vstack([mean - ci[:, 0], ci[:, 1] - mean])
        left.errorbar(x, mean, yerr=np.maximum(yerr, 0.0), fmt='-o', ms=3.5, capsize=3,
                      lw=1.2, color=COLORS.get(name), label=LABELS.get(name, name))
    left.set_xlabel('noise level (std of v, V)')
    if acquisition:
        left.set_ylabel('runs acquired within 10 s (%)')
        left.set_title('acquisition from a cold start against noise\n(error bars: 95 % Wilson '
                       'interval; acquired: 1 s in a row within 15 deg)', fontsize=10)
    else:
        left.set_ylabel('samples tracked: off-axis angle <= 15 deg (%)')
        left.set_title('tracking against noise (error bars: 95 % bootstrap interval)',
                       fontsize=10)
    left.set_ylim(0, 102)
    left.grid(alpha=0.3)
    left.legend(fontsize=8, loc='lower left')
    for name, traj in runs.items():
        d = traj.error[:, 0, :]
        right.plot(d[:, 0], d[:, 1], lw=0.9, color=COLORS.get(name),
                   label=LABELS.get(name, name))
        right.plot(d[-1, 0], d[-1, 1], 's', ms=5, color=COLORS.get(name))
    first = next(iter(runs.values())).error[0, 0, :]
    right.plot(first[0], first[1], 'k*', ms=10, label='start (same for all)')
    phase = np.linspace(0.0, 2.0 * np.pi, 200)
    cone = led.TRACKING_ANGLE
    right.plot(cone * np.cos(phase), cone * np.sin(phase), color='tab:red', ls=':', lw=1.0,
               label=f'{cone:g} deg tracking cone')
    right.plot(0.0, 0.0, 'r+', ms=10, label='the LED (the source)')
    # a zoom on the LED: the EKFs' paths are within a few degrees of it
    zoom = right.inset_axes((0.04, 0.04, 0.3, 0.3))
    for name, traj in runs.items():
        d = traj.error[:, 0, :]
        zoom.plot(d[:, 0], d[:, 1], lw=0.7, color=COLORS.get(name))
    zoom.plot(0.0, 0.0, 'r+', ms=8)
    zoom.set_xlim(-ZOOM, ZOOM)
    zoom.set_ylim(-ZOOM, ZOOM)
    zoom.set_aspect('equal')
    zoom.tick_params(labelsize=7)
    zoom.set_xlabel('azimuth (deg)', fontsize=6, labelpad=1)
    zoom.set_ylabel('elevation (deg)', fontsize=6, labelpad=1)
    zoom.set_title(f'zoom on the LED, +-{ZOOM:g} deg', fontsize=7)
    right.set_aspect('equal', adjustable='datalim')
    right.set_xlabel('azimuth error on the sky, (a - a_s) cos e_s (deg)')
    right.set_ylabel('elevation error, e - e_s (deg)')
    right.grid(alpha=0.3)
    right.set_title(f'mean pointing relative to the source: {run_title}\n'
                    '(squares: the end)', fontsize=10)
    right.legend(fontsize=8, loc='upper right')
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig
