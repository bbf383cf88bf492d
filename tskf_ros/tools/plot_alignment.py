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
plot_bag's figure of a one-axis alignment bag (Solanki et al. Fig. 8), from streamed rows.

The node's EKF estimates (x2 in rad on the wire) are read in V and deg
(conversions.msg_to_alignment_state); the truth is the simulator's JointState, its
angles in rad (REP 103) drawn in deg; the intensity is the photodiode's Illuminance.  Each
message becomes a row of floats as it is read (plot_rows.stream); a series longer than
plot_rows.DRAWN points is drawn as its envelope.
"""

from typing import Any, Optional

from matplotlib.figure import Figure
import matplotlib.pyplot as plt
import numpy as np

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.tools.plot_rows import band, drawn_note, envelope, RowKind


def _estimate(msg: Any) -> tuple:
    """Return an alignment estimate's row: (t s, x1 V, x2 deg, sd of x1, sd of x2)."""
    e = conversions.msg_to_alignment_state(msg)
    return (e.stamp_ns / NS, float(e.x[0]), float(e.x[1]),
            float(np.sqrt(max(e.P[0, 0], 0.0))), float(np.sqrt(max(e.P[1, 1], 0.0))))


ESTIMATE = RowKind(_estimate, 5)


def truth_kind(names: list[str]) -> RowKind:
    """Return the row of a truth JointState whose joints are `names`: (t s, angles rad)."""
    count = len(names)

    def read(msg: Any) -> tuple:
        if len(msg.position) != count:
            raise ValueError(f'{len(msg.position)} positions, the first message had {count}')
        return (conversions.stamp_to_ns(msg.header.stamp) / NS, *map(float, msg.position))
    return RowKind(read, count + 1)


def alignment_figure(estimates: np.ndarray, title: str, *, truth: np.ndarray,
                     names: list[str], intensity: np.ndarray,
                     recorded: Optional[np.ndarray] = None,
                     label: str = 'EKF') -> Figure:
    """
    Draw an alignment run: x1hat, x2hat, the true angle of incidence, V_d; return the figure.

    estimates and recorded: rows of ESTIMATE (recorded: the bag's own, dashed beside a
    replay's); truth: rows of truth_kind(names); intensity: rows (t s, V).
    """
    t, x, sd = estimates[:, 0], estimates[:, 1:3], estimates[:, 3:5]
    tt, tv = truth[:, 0], truth[:, 1:]
    pos = {n: i for i, n in enumerate(names)}
    t0 = t.min()
    fig, axes = plt.subplots(4, 1, figsize=(10, 11), sharex=True)
    # the truth's angles are in rad (REP 103), drawn in deg; the intensity factor is in V
    for ax, i, name, key, unit, scale in (
            (axes[0], 0, 'x1hat', 'intensity_factor', 'V', 1.0),
            (axes[1], 1, 'x2hat', 'scan_mean', 'deg', np.rad2deg(1.0))):
        ax.plot(*envelope(t - t0, x[:, i]), 'C3-', lw=1, label=f'{name} ({label})')
        if recorded is not None and len(recorded):
            ax.plot(*envelope(recorded[:, 0] - t0, recorded[:, 1 + i]), 'C0--', lw=0.8,
                    label=f'{name} of the recorded run')
        ax.fill_between(*band(t - t0, x[:, i], 2 * sd[:, i]), color='C3', alpha=0.2,
                        label='+-2 sigma')
        if key in pos:
            ax.plot(*envelope(tt - t0, tv[:, pos[key]] * scale), 'k-', lw=1,
                    label=f'true {key}')
        ax.set_ylabel(f'{name} ({unit})')
        ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    if 'incidence' in pos:
        axes[2].plot(*envelope(tt - t0, np.rad2deg(tv[:, pos['incidence']])), 'k-', lw=1,
                     label='true angle of incidence')
    axes[2].axhspan(-15, 15, color='C2', alpha=0.1, label='tracking zone +-15 deg')
    axes[2].set_ylabel('true angle of incidence (deg)')
    axes[2].legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    axes[3].plot(*envelope(intensity[:, 0] - t0, intensity[:, 1]), '.', color='C0', ms=3,
                 label='measured intensity V_d')
    axes[3].set_ylabel('intensity (V)')
    axes[3].set_xlabel('time (s)')
    axes[3].legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title + drawn_note(max(len(t), len(tt), len(intensity))))
    fig.tight_layout()
    return fig
