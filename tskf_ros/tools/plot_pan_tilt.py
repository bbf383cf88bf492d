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
plot_bag's figure of a two-axis (pan-tilt) alignment bag.

The estimate is the conical-scan EKF's [x1, d_c, d_e, b_c, b_e] (the estimate layout of
pan_tilt_messages, read back in V and deg); the truth, where the bag has one, is the
simulator's JointState: the two joints (the conical scan included), the source's azimuth
and elevation, and the off-axis angle.  The true pointing error drawn beside the EKF's
[d_c, d_e] is that of the boresight, scan included: it circles the mean error the EKF
estimates with the scan's radius.
"""

import math
from typing import Any

from matplotlib.figure import Figure
import matplotlib.pyplot as plt
import numpy as np

from tskf_ros.core.units import NS
from tskf_ros.led.two_axis.pointing_geometry import tangent_error
from tskf_ros.messages.pan_tilt_messages import (msg_to_pan_tilt_state, msg_to_pan_tilt_truth,
                                                 OFF_AXIS, SOURCE_JOINTS)
from tskf_ros.tools.plot_rows import band, drawn_note, envelope, RowKind

TRACKING_ZONE = 15.0    # deg: the off-axis angle within which a sample counts as tracked


def is_pan_tilt_estimate(msg: Any) -> bool:
    """Tell whether a message is a two-axis alignment estimate."""
    try:
        msg_to_pan_tilt_state(msg)
    except (ValueError, IndexError):
        return False
    return True


def _estimate(msg: Any) -> tuple:
    """Return an estimate's row: (t s, x1, d_c, d_e, and their standard deviations)."""
    e = msg_to_pan_tilt_state(msg)
    sd = np.sqrt(np.diag(e.P)[:3].clip(0))
    return (e.stamp_ns / NS, *map(float, e.x[:3]), *map(float, sd))


def _truth(msg: Any) -> tuple:
    """Return the truth's row: (t s, true d_c, d_e and off-axis angle, deg), NaN if not one."""
    stamp, angles = msg_to_pan_tilt_truth(msg)
    if len(angles) != 5 or not {OFF_AXIS, *SOURCE_JOINTS} <= set(angles):
        return stamp / NS, math.nan, math.nan, math.nan
    # the two joints come first, in the order of pan_tilt.joints: [pan, tilt]
    pan, tilt = [v for k, v in angles.items() if k not in SOURCE_JOINTS and k != OFF_AXIS]
    d = tangent_error(pan, tilt, angles[SOURCE_JOINTS[0]], angles[SOURCE_JOINTS[1]])
    return stamp / NS, float(d[0]), float(d[1]), float(angles[OFF_AXIS])


ESTIMATE = RowKind(_estimate, 7)
TRUTH = RowKind(_truth, 4)


def pan_tilt_figure(estimates: np.ndarray, truth: np.ndarray, intensity: np.ndarray,
                    title: str) -> Figure:
    """
    Draw a two-axis alignment run: x1, the pointing error, the off-axis angle, V_d.

    estimates: rows of ESTIMATE; truth: rows of TRUTH (NaN rows are left out); intensity:
    rows (t s, V) of plot_estimator.POWER.
    """
    t, x, sd = estimates[:, 0], estimates[:, 1:4], estimates[:, 4:7]
    t0 = t.min()
    fig, axes = plt.subplots(4, 1, figsize=(10, 11), sharex=True)
    axes[0].plot(*envelope(t - t0, x[:, 0]), 'C3-', lw=1, label='x1hat (EKF)')
    axes[0].fill_between(*band(t - t0, x[:, 0], 2 * sd[:, 0]), color='C3', alpha=0.2,
                         label='+-2 sigma')
    axes[0].set_ylabel('intensity factor x1 (V)')
    truth = truth[np.isfinite(truth[:, 1])]
    tt, true_d, off_axis = truth[:, 0], truth[:, 1:3], truth[:, 3]
    for i, (name, color) in enumerate((('d_c, cross-elevation', 'C0'),
                                       ('d_e, elevation', 'C1')), start=1):
        axes[1].plot(*envelope(t - t0, x[:, i]), '-', color=color, lw=1,
                     label=f'{name} (EKF)')
        axes[1].fill_between(*band(t - t0, x[:, i], 2 * sd[:, i]), color=color, alpha=0.15,
                             label='+-2 sigma')
        if tt.size:
            axes[1].plot(*envelope(tt - t0, true_d[:, i - 1]), ':', color=color, lw=0.8,
                         label=f'true {name.split(",")[0]} of the boresight (scan included)')
    axes[1].set_ylabel('pointing error (deg)')
    if tt.size:
        axes[2].plot(*envelope(tt - t0, off_axis), 'k-', lw=1, label='true off-axis angle')
    axes[2].axhspan(0, TRACKING_ZONE, color='C2', alpha=0.1,
                    label=f'tracking zone <= {TRACKING_ZONE:g} deg')
    axes[2].set_ylabel('off-axis angle (deg)')
    axes[3].plot(*envelope(intensity[:, 0] - t0, intensity[:, 1]), '.', color='C0', ms=3,
                 label='measured intensity V_d')
    axes[3].set_ylabel('intensity (V)')
    axes[3].set_xlabel('time (s)')
    for ax in axes:
        ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
        ax.grid(alpha=0.3)
    fig.suptitle(title + drawn_note(max(len(t), len(tt), len(intensity))))
    fig.tight_layout()
    return fig
