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
The two-axis LED link as a plant: a seeded stream of samples for a pan-tilt receiver.

The two-axis form of led_link and of Solanki et al.'s eq. (25) (IEEE/ASME T-Mech 2018):
the source direction (a_s, e_s) drifts at beta degrees per second on each joint axis
(a sign drawn per run and axis), plus a random walk w2 per axis in its tangent plane
(Table I's Q_sys per nominal step dt); the intensity factor walks as x1 <- |x1 + w1|;
sample k reads z_k = x1 g_r(theta_k) + v_k, theta_k the exact off-axis angle of the
receiver's boresight (pointing_geometry) and g_r the radial response.  The mount follows
position commands [pan, tilt] (degrees) at the next sample.  Stamps are k dt, or with
`jitter` k dt + U(-jitter, jitter); the plant moves by the elapsed time (drift times
mu, walks with variance times mu, mu = elapsed / dt).  The random numbers are drawn in a
fixed order per sample (jitter, w1, w2, v, dropout), whatever the commands, so aligners
run on one seed see the same link.  Vectorised over runs.
"""

from dataclasses import dataclass
import math
from typing import Optional, Union

import numpy as np
from numpy.typing import NDArray

from tskf_ros.led.intensity_model import AlignmentError, FloatArray, MAX_INTENSITY
from tskf_ros.led.scanning_ekf import PAPER_DT, PAPER_Q_SYS
from tskf_ros.led.two_axis.pointing_geometry import (displaced, joint_turn, MAX_ELEVATION,
                                                     off_axis_angle, tangent_error,
                                                     uniform_in_cone)
from tskf_ros.led.two_axis.radial_response import RadialResponse

# quoted: numpy.random loads when a seed is drawn, not when a node's modules import
Seed = Union[None, int, 'np.random.SeedSequence', 'np.random.Generator']


@dataclass(frozen=True)
class PanTiltLinkConfig:
    """The simulated two-axis link; angles in degrees, intensities in volts, time in s."""

    beta: float = 1.2                  # deg/s per joint axis, sign random per run and axis
    dt: float = PAPER_DT
    steps: int = 400                   # samples of a simulate_pan_tilt run
    noise: float = 0.2                 # sigma of v (V)
    q_sys: tuple[float, float] = (PAPER_Q_SYS[0][0], PAPER_Q_SYS[1][1])   # w1, w2 per step
    max_intensity: float = MAX_INTENSITY
    offset0: float = 5.0               # deg: angle of the source off the boresight at sample 0
    cone: float = 0.0                  # > 0: a cold start, the source uniform in this cone
    elevation0: float = 20.0           # deg: the receiver's tilt at sample 0 (pan 0)
    dropout: float = 0.0               # probability that a sample is missing
    blocked: tuple[float, ...] = ()    # [start, stop) s with no light
    jitter: float = 0.0                # s: stamps k dt + U(-jitter, jitter), < dt / 2

    def __post_init__(self) -> None:
        """Check the parameters; raise AlignmentError with the reason."""
        for name in ('beta', 'dt', 'noise', 'max_intensity', 'offset0', 'cone',
                     'elevation0', 'dropout', 'jitter'):
            if not math.isfinite(getattr(self, name)):
                raise AlignmentError(f'{name} must be finite, got {getattr(self, name)}')
        if self.steps < 1 or not self.dt > 0.0:
            raise AlignmentError('steps must be >= 1 and dt > 0')
        if self.noise < 0.0 or min(self.q_sys) < 0.0 or not self.max_intensity > 0.0:
            raise AlignmentError('noise and q_sys must be >= 0, max_intensity > 0')
        if not 0.0 <= self.dropout < 1.0:
            raise AlignmentError(f'dropout must be in [0, 1), got {self.dropout}')
        if not 0.0 <= self.jitter < self.dt / 2:
            raise AlignmentError(f'jitter must be in [0, dt/2), got {self.jitter}')
        if not 0.0 <= max(self.offset0, self.cone) < 90.0:
            raise AlignmentError('offset0 and cone must be in [0, 90) deg')
        if abs(self.elevation0) > MAX_ELEVATION - 30.0:
            raise AlignmentError(f'elevation0 must be within +-{MAX_ELEVATION - 30.0:g} deg, '
                                 'so that the drift stays clear of the keyhole')
        if self.blocked and (len(self.blocked) != 2 or not self.blocked[0] < self.blocked[1]):
            raise AlignmentError(f'blocked must be [start, stop) s, got {list(self.blocked)}')


@dataclass(frozen=True)
class PanTiltSample:
    """One sample of every run (arrays over runs): the truth and what the photodiode reads."""

    index: int                 # sample number k
    t: float                   # s: its stamp since sample 0
    joints: FloatArray         # (runs, 2) [pan, tilt] of the receiver (deg)
    source: FloatArray         # (runs, 2) [a_s, e_s] of the source (deg)
    theta: FloatArray          # exact off-axis angle of the boresight (deg)
    error: FloatArray          # (runs, 2) tangent-plane error of the boresight (deg)
    x1: FloatArray             # intensity factor
    clean: FloatArray          # x1 g_r(theta) (V), 0 while blocked
    reading: FloatArray        # clean + v (V)
    missing: NDArray[np.bool_]  # lost to a dropout: never reaches the receiver

    @property
    def z(self) -> FloatArray:
        """Return the reading where it arrived, NaN where it is missing."""
        return np.where(self.missing, np.nan, self.reading)


class PanTiltLink:
    """A seeded, resumable two-axis link; `command` moves the mount, `sample` reads it."""

    def __init__(self, config: PanTiltLinkConfig = PanTiltLinkConfig(), *, runs: int = 1,
                 seed: Seed = 0, response: Optional[RadialResponse] = None) -> None:
        self.config = c = config
        self.runs = n = int(runs)
        if n < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self.response = response if response is not None else RadialResponse()
        self.rng = np.random.default_rng(seed)
        sign = np.where(self.rng.random((n, 2)) < 0.5, -1.0, 1.0)
        if c.cone > 0.0:
            d0 = uniform_in_cone(c.cone, n, self.rng)
        else:
            phase = self.rng.uniform(0.0, 2.0 * np.pi, n)
            d0 = c.offset0 * np.stack([np.cos(phase), np.sin(phase)], axis=-1)
        self.joints = np.zeros((n, 2))
        self.joints[:, 1] = c.elevation0
        self.target = self.joints.copy()
        # the source at the exact angle |d0| from the boresight, toward -d0
        self.source = displaced(self.joints[:, 0], self.joints[:, 1], -d0)
        self.rate = sign * c.beta * c.dt             # joint degrees per nominal step
        self.x1 = np.full(n, c.max_intensity / self.response.peak)
        self.obstructed = False                      # no light while True (set at run time)
        self._k = 0
        self._t = 0.0

    @property
    def count(self) -> int:
        """Return the number of samples taken so far."""
        return self._k

    def command(self, joints: FloatArray) -> None:
        """Take position commands [pan, tilt] (deg), (2,) or (runs, 2); tilt kept in range."""
        joints = np.broadcast_to(np.asarray(joints, dtype=float), (self.runs, 2)).copy()
        if not np.all(np.isfinite(joints)):
            raise AlignmentError(f'joint commands must be finite, got {joints.tolist()}')
        joints[:, 1] = np.clip(joints[:, 1], -MAX_ELEVATION, MAX_ELEVATION)
        self.target = joints

    def command_turn(self, turn: FloatArray) -> None:
        """Command the tangent-plane turns [du_c, du_e] (runs, 2) from the current joints."""
        self.command(self.joints + joint_turn(np.asarray(turn, dtype=float),
                                              self.joints[:, 1]))

    def sample(self) -> PanTiltSample:
        """Move the plant to the next stamp (not before sample 0), then take the sample."""
        c, n, rng = self.config, self.runs, self.rng
        k = self._k
        u_jitter = rng.random()
        w1 = rng.standard_normal(n) * math.sqrt(c.q_sys[0])
        w2 = rng.standard_normal((n, 2)) * math.sqrt(c.q_sys[1])
        v = rng.standard_normal(n) * c.noise
        missing = rng.random(n) < c.dropout
        t = k * c.dt + (c.jitter * (2.0 * u_jitter - 1.0) if k > 0 else 0.0)
        if k > 0:
            self._advance((t - self._t) / c.dt, w1, w2)
        theta = off_axis_angle(self.joints[:, 0], self.joints[:, 1], self.source[:, 0],
                               self.source[:, 1])
        blocked = self.obstructed or (bool(c.blocked) and c.blocked[0] <= t < c.blocked[1])
        # (5)/(8) along theta: z = x1 g_r(theta) + v
        clean = np.zeros(n) if blocked else self.x1 * self.response.g(theta)
        self._k, self._t = k + 1, t
        error = tangent_error(self.joints[:, 0], self.joints[:, 1], self.source[:, 0],
                              self.source[:, 1])
        return PanTiltSample(k, t, self.joints.copy(), self.source.copy(), theta, error,
                             self.x1.copy(), clean, clean + v, missing)

    def drift(self) -> FloatArray:
        """Return the source's tangent-plane drift per nominal step (runs, 2), degrees."""
        return np.stack([self.rate[:, 0] * np.cos(np.radians(self.source[:, 1])),
                         self.rate[:, 1]], axis=-1)

    def _advance(self, mu: float, w1: FloatArray, w2: FloatArray) -> None:
        """Over mu nominal steps: the mount reaches its target, the source drifts and walks."""
        c = self.config
        self.joints = self.target.copy()
        self.source = self.source + mu * self.rate + joint_turn(math.sqrt(mu) * w2,
                                                                self.source[:, 1])
        # a drift that would carry the source into the keyhole turns back
        over = np.abs(self.source[:, 1]) > MAX_ELEVATION - 10.0
        self.rate[over, 1] = -np.sign(self.source[over, 1]) * abs(c.beta * c.dt)
        self.x1 = np.abs(self.x1 + math.sqrt(mu) * w1)
