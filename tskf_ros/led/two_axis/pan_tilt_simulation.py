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

The two-axis form of Solanki et al.'s eq. (25) (IEEE/ASME T-Mech 2018): the source
direction (a_s, e_s) drifts at beta degrees per second on each joint axis, with a sign
drawn per run and axis, plus a random walk w2 per axis (Table I's Q_sys per step, in the
tangent plane); the intensity factor walks as x1 <- |x1 + w1|; the sample is
z_k = x1 g_r(theta_k) + v_k with theta_k the exact off-axis angle of the receiver (its
mean pointing plus the scan offset) and g_r the radial response.  The aligner returns
tangent-plane turns, which the mount executes as joint turns at its elevation.  All noise
is drawn up front in a fixed order, so aligners run with one seed see the same link.
"""

from dataclasses import dataclass
import math
from typing import Optional, Protocol

import numpy as np

from tskf_ros.led.intensity_model import (AlignmentError, FloatArray, MAX_INTENSITY,
                                          TRACKING_ANGLE)
from tskf_ros.led.scanning_ekf import Measurement, PAPER_DT, PAPER_Q_SYS
from tskf_ros.led.two_axis.pointing_geometry import (joint_turn, MAX_ELEVATION,
                                                     off_axis_angle, tangent_error,
                                                     uniform_in_cone)
from tskf_ros.led.two_axis.radial_response import RadialResponse


class TwoAxisAligner(Protocol):
    """What the simulation needs from a two-axis alignment algorithm."""

    runs: int

    @property
    def scan_offset(self) -> FloatArray:
        """Tangent-plane offset (2,) or (runs, 2) of the receiver from its mean pointing."""

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Take the sample at `stamp` (NaN/None: missing); return the turns (runs, 2)."""


@dataclass(frozen=True)
class PanTiltLinkConfig:
    """The simulated two-axis link; angles in degrees, intensities in volts, time in s."""

    beta: float = 1.2                  # deg/s per joint axis, sign random per run and axis
    dt: float = PAPER_DT
    steps: int = 400
    noise: float = 0.2                 # sigma of v (V)
    q_sys: tuple[float, float] = (PAPER_Q_SYS[0][0], PAPER_Q_SYS[1][1])   # w1, w2 per step
    max_intensity: float = MAX_INTENSITY
    offset0: float = 5.0               # |d| of the mean pointing at sample 0, random direction
    cone: float = 0.0                  # > 0: a cold start, d_0 uniform in this cone instead
    source_elevation: float = 20.0     # e_s at sample 0; a_s starts at 0
    dropout: float = 0.0               # probability that a sample is missing
    blocked: tuple[float, ...] = ()    # [start, stop) s with no light

    def __post_init__(self) -> None:
        """Check the parameters; raise AlignmentError with the reason."""
        for name in ('beta', 'dt', 'noise', 'max_intensity', 'offset0', 'cone',
                     'source_elevation', 'dropout'):
            if not math.isfinite(getattr(self, name)):
                raise AlignmentError(f'{name} must be finite, got {getattr(self, name)}')
        if self.steps < 1 or not self.dt > 0.0:
            raise AlignmentError('steps must be >= 1 and dt > 0')
        if not 0.0 <= self.dropout < 1.0:
            raise AlignmentError(f'dropout must be in [0, 1), got {self.dropout}')
        if abs(self.source_elevation) > MAX_ELEVATION - 30.0:
            raise AlignmentError(f'source_elevation must be within +-{MAX_ELEVATION - 30.0:g} '
                                 'deg, so that its drift stays clear of the keyhole')


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


def simulate_pan_tilt(aligner: TwoAxisAligner, link: PanTiltLinkConfig,
                      rng: np.random.Generator,
                      response: Optional[RadialResponse] = None) -> PanTiltTrajectory:
    """Run the aligner in closed loop with the two-axis link for link.steps samples."""
    response = response if response is not None else RadialResponse()
    n, steps = aligner.runs, int(link.steps)
    w1 = rng.standard_normal((steps, n)) * math.sqrt(link.q_sys[0])
    w2 = rng.standard_normal((steps, n, 2)) * math.sqrt(link.q_sys[1])
    v = rng.standard_normal((steps, n)) * link.noise
    missing = rng.random((steps, n)) < link.dropout
    sign = np.where(rng.random((n, 2)) < 0.5, -1.0, 1.0)
    if link.cone > 0.0:
        d0 = uniform_in_cone(link.cone, n, rng)
    else:
        phase = rng.uniform(0.0, 2.0 * np.pi, n)
        d0 = link.offset0 * np.stack([np.cos(phase), np.sin(phase)], axis=-1)
    t = np.arange(steps, dtype=float) * link.dt
    out = PanTiltTrajectory(
        t=t, theta=np.empty((steps, n)), theta_mean=np.empty((steps, n)),
        error=np.empty((steps, n, 2)), drift=np.empty((steps, n, 2)), x1=np.empty((steps, n)),
        clean=np.empty((steps, n)), z=np.empty((steps, n)), turn=np.empty((steps, n, 2)))
    src = np.zeros((n, 2))
    src[:, 1] = link.source_elevation
    rate = sign * link.beta * link.dt                   # joint degrees per step
    mean = src + joint_turn(d0, src[:, 1])              # the mean pointing's joints
    x1 = np.full(n, link.max_intensity / response.peak)
    for k in range(steps):
        offset = np.broadcast_to(aligner.scan_offset, (n, 2))
        actual = mean + joint_turn(offset, mean[:, 1])
        theta = off_axis_angle(actual[:, 0], actual[:, 1], src[:, 0], src[:, 1])
        clean = x1 * response.g(theta)
        if link.blocked and link.blocked[0] <= t[k] < link.blocked[1]:
            clean = np.zeros(n)
        z = np.where(missing[k], np.nan, clean + v[k])
        out.theta[k] = theta
        out.theta_mean[k] = off_axis_angle(mean[:, 0], mean[:, 1], src[:, 0], src[:, 1])
        out.error[k] = tangent_error(mean[:, 0], mean[:, 1], src[:, 0], src[:, 1])
        out.drift[k] = np.stack([rate[:, 0] * np.cos(np.radians(src[:, 1])), rate[:, 1]], -1)
        out.x1[k], out.clean[k], out.z[k] = x1, clean, z
        turn = np.asarray(aligner.step(float(t[k]), z), dtype=float).reshape(n, 2)
        out.turn[k] = turn
        # the mean pointing turns by the turn less the scan's own step s_{k+1} - s_k
        step_of_scan = np.broadcast_to(aligner.scan_offset, (n, 2)) - offset
        mean = mean + joint_turn(turn - step_of_scan, mean[:, 1])
        # the source: drift, and a random walk w2 in its tangent plane
        src = src + rate + joint_turn(w2[k], src[:, 1])
        # a drift that would carry the source into the keyhole turns back
        over = np.abs(src[:, 1]) > MAX_ELEVATION - 10.0
        rate[over, 1] = -np.sign(src[over, 1]) * abs(link.beta * link.dt)
        x1 = np.abs(x1 + w1[k])
    return out


def tracking_fraction(traj: PanTiltTrajectory, *, angle: float = TRACKING_ANGLE) -> FloatArray:
    """Per run: the fraction of samples with the receiver within `angle` of the source."""
    return np.mean(traj.theta <= angle, axis=0)
