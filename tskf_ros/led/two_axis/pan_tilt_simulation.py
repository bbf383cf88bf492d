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
The closed loop of a pan-tilt receiver and a drifting LED, on the sphere.

The two-axis form of Solanki et al.'s eq. (25) (IEEE/ASME T-Mech 2018): `simulate_pan_tilt`
steps a PanTiltLink (pan_tilt_link) against an aligner that returns tangent-plane turns,
which the mount executes as joint turns at its elevation; one run of it is the same as
stepping the link by hand with the same seed.  The aligner's mean pointing is the
boresight less its scan offset.
"""

from dataclasses import dataclass
from typing import Optional, Protocol

import numpy as np

from tskf_ros.led.intensity_model import FloatArray, TRACKING_ANGLE
from tskf_ros.led.scanning_ekf import Measurement
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig, Seed
from tskf_ros.led.two_axis.pointing_geometry import joint_turn, off_axis_angle, tangent_error
from tskf_ros.led.two_axis.radial_response import RadialResponse


class TwoAxisAligner(Protocol):
    """What the simulation needs from a two-axis alignment algorithm."""

    runs: int

    @property
    def scan_offset(self) -> FloatArray:
        """Tangent-plane offset (2,) or (runs, 2) of the receiver from its mean pointing."""

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Take the sample at `stamp` (NaN/None: missing); return the turns (runs, 2)."""


@dataclass
class PanTiltTrajectory:
    """One simulation: time (steps,), per-step and per-run arrays (steps, runs[, k])."""

    t: FloatArray
    theta: FloatArray         # exact off-axis angle of the receiver (with the scan)
    theta_mean: FloatArray    # exact off-axis angle of the mean pointing
    error: FloatArray         # (steps, runs, 2): tangent-plane error d of the mean pointing
    drift: FloatArray         # (steps, runs, 2): the source's tangent-plane drift per step
    x1: FloatArray
    clean: FloatArray         # x1 g_r(theta) (V)
    z: FloatArray             # the sample given to the aligner, NaN when missing
    turn: FloatArray          # (steps, runs, 2): tangent-plane turn returned by the aligner


def simulate_pan_tilt(aligner: TwoAxisAligner, link: PanTiltLinkConfig, seed: Seed,
                      response: Optional[RadialResponse] = None) -> PanTiltTrajectory:
    """Run the aligner in closed loop with a PanTiltLink(link, seed) for link.steps samples."""
    n, steps = aligner.runs, int(link.steps)
    plant = PanTiltLink(link, runs=n, seed=seed, response=response)
    shape = (steps, n)
    out = PanTiltTrajectory(
        t=np.empty(steps), theta=np.empty(shape), theta_mean=np.empty(shape),
        error=np.empty(shape + (2,)), drift=np.empty(shape + (2,)), x1=np.empty(shape),
        clean=np.empty(shape), z=np.empty(shape), turn=np.empty(shape + (2,)))
    for k in range(steps):
        s = plant.sample()
        offset = np.broadcast_to(aligner.scan_offset, (n, 2))
        # the mean pointing: the boresight less the scan offset
        mean = s.joints - joint_turn(offset, s.joints[:, 1])
        out.t[k], out.theta[k], out.x1[k], out.clean[k] = s.t, s.theta, s.x1, s.clean
        out.z[k] = z = s.z
        out.theta_mean[k] = off_axis_angle(mean[:, 0], mean[:, 1], s.source[:, 0],
                                           s.source[:, 1])
        out.error[k] = tangent_error(mean[:, 0], mean[:, 1], s.source[:, 0], s.source[:, 1])
        out.drift[k] = plant.drift()
        turn = np.asarray(aligner.step(s.t, z), dtype=float).reshape(n, 2)
        out.turn[k] = turn
        plant.command_turn(turn)
    return out


def tracking_fraction(traj: PanTiltTrajectory, *, angle: float = TRACKING_ANGLE) -> FloatArray:
    """Per run: the fraction of samples with the receiver within `angle` of the source."""
    return np.mean(traj.theta <= angle, axis=0)
