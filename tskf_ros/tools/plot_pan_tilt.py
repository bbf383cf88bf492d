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

from typing import Optional

from matplotlib.figure import Figure
import matplotlib.pyplot as plt
import numpy as np

from tskf_ros.core.units import NS
from tskf_ros.led.two_axis.pointing_geometry import tangent_error
from tskf_ros.messages import conversions
from tskf_ros.messages.pan_tilt_messages import (msg_to_pan_tilt_state, msg_to_pan_tilt_truth,
                                                 OFF_AXIS, SOURCE_JOINTS)

TRACKING_ZONE = 15.0    # deg: the off-axis angle within which a sample counts as tracked


def is_pan_tilt_estimate(msgs: list) -> bool:
    """Tell whether the first of [(log ns, message)] is a two-axis alignment estimate."""
    if not msgs:
        return False
    try:
        msg_to_pan_tilt_state(msgs[0][1])
    except (ValueError, IndexError):
        return False
    return True


def pan_tilt_figure(estimates: list, truth: list, intensity: list, title: str) -> Figure:
    """Draw a two-axis alignment run: x1, the pointing error, the off-axis angle, V_d."""
    rows = [msg_to_pan_tilt_state(m) for _, m in estimates]
    t = np.array([r.stamp_ns for r in rows], float) / NS
    x = np.array([r.x for r in rows])
    sd = np.sqrt(np.array([np.diag(r.P) for r in rows]).clip(0))
    t0 = t.min()
    fig, axes = plt.subplots(4, 1, figsize=(10, 11), sharex=True)
    axes[0].plot(t - t0, x[:, 0], 'C3-', lw=1, label='x1hat (EKF)')
    axes[0].fill_between(t - t0, x[:, 0] - 2 * sd[:, 0], x[:, 0] + 2 * sd[:, 0], color='C3',
                         alpha=0.2, label='+-2 sigma')
    axes[0].set_ylabel('intensity factor x1 (V)')
    tt, true_d, off_axis = _truth(truth)
    for i, (name, color) in enumerate((('d_c, cross-elevation', 'C0'),
                                       ('d_e, elevation', 'C1')), start=1):
        axes[1].plot(t - t0, x[:, i], '-', color=color, lw=1, label=f'{name} (EKF)')
        axes[1].fill_between(t - t0, x[:, i] - 2 * sd[:, i], x[:, i] + 2 * sd[:, i],
                             color=color, alpha=0.15, label='+-2 sigma')
        if true_d is not None:
            axes[1].plot(tt - t0, true_d[:, i - 1], ':', color=color, lw=0.8,
                         label=f'true {name.split(",")[0]} of the boresight (scan included)')
    axes[1].set_ylabel('pointing error (deg)')
    if off_axis is not None:
        axes[2].plot(tt - t0, off_axis, 'k-', lw=1, label='true off-axis angle')
    axes[2].axhspan(0, TRACKING_ZONE, color='C2', alpha=0.1,
                    label=f'tracking zone <= {TRACKING_ZONE:g} deg')
    axes[2].set_ylabel('off-axis angle (deg)')
    tz = np.array([conversions.msg_to_power(m)[0] for _, m in intensity], float) / NS
    vz = np.array([conversions.msg_to_power(m)[1] for _, m in intensity])
    axes[3].plot(tz - t0, vz, '.', color='C0', ms=3, label='measured intensity V_d')
    axes[3].set_ylabel('intensity (V)')
    axes[3].set_xlabel('time (s)')
    for ax in axes:
        ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _truth(truth: list) -> tuple[np.ndarray, Optional[np.ndarray], Optional[np.ndarray]]:
    """Return the truth's times (s), true [d_c, d_e] and off-axis angle (deg), or Nones."""
    rows = [msg_to_pan_tilt_truth(m) for _, m in truth]
    names = {OFF_AXIS, *SOURCE_JOINTS}
    rows = [(stamp, angles) for stamp, angles in rows
            if len(angles) == 5 and names <= set(angles)]
    if not rows:
        return np.zeros(0), None, None
    t = np.array([stamp for stamp, _ in rows], float) / NS
    # the two joints come first, in the order of pan_tilt.joints: [pan, tilt]
    joints = np.array([[v for k, v in a.items() if k not in SOURCE_JOINTS and k != OFF_AXIS]
                       for _, a in rows])
    source = np.array([[a[s] for s in SOURCE_JOINTS] for _, a in rows])
    d = tangent_error(joints[:, 0], joints[:, 1], source[:, 0], source[:, 1])
    return t, d, np.array([a[OFF_AXIS] for _, a in rows])
