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
A conical-scan EKF: the intensity and the two pointing errors of a pan-tilt receiver.

The two-axis form of the scanning EKF of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018,
Section IV, eq. (7)-(21)); the geometry is in `pointing_geometry`, the response in
`radial_response`.  State, in the tangent plane at the source (degrees, volts):

    x = [x1, d_c, d_e, v_c, v_e]

x1 the intensity factor of eq. (5)/(6), d the error of the mean pointing, v the source's
drift per nominal step dt.  The receiver scans a circle of radius r around its mean
pointing, s_k = r [cos phi_k, sin phi_k] (`conical_scan`), and each sample is

    z_k = x1 g_r(|d_k + s_k|) + v_k,                          R = sigma^2

(one scalar per sample, not the paper's pair (12): the scan's rotation makes d observable
over a turn, and the pair's reuse of z_{k-1} would correlate successive noises).  Over
mu = elapsed / dt nominal steps (mu from the stamps, as the time-scale filter):

    x1 <- x1,   d <- d + u_{k-1} - mu v,   v <- v,   P <- F P F^T + mu Q

with u the turn of the mean pointing commanded at the previous sample.  The control is the
paper's P law (21) on each axis, u_k = -G dhat_k, plus (optional, not in the paper) the
estimated drift of one step, + vhat_k.  The receiver is sent u_k + s_{k+1} - s_k.
Predict and update are tskf_ros.core.kalman's, batched over independent runs.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import kalman
from tskf_ros.led.intensity_model import AlignmentError, FloatArray, IncidenceResponse
from tskf_ros.led.scanning_ekf import as_measurement, Measurement, PAPER_DT, StampClock
from tskf_ros.led.two_axis.pointing_geometry import conical_scan
from tskf_ros.led.two_axis.radial_response import RadialResponse

STATES = ('x1', 'd_c', 'd_e', 'v_c', 'v_e')


@dataclass(frozen=True)
class ConicalEKFConfig:
    """The conical-scan EKF's parameters; angles in degrees, intensities in volts."""

    radius: float = 2.0               # r of the scan circle
    points: int = 20                  # samples per scan turn (1 s at 50 ms, as Psi)
    x0: tuple[float, ...] = (2.0, 0.0, 0.0, 0.0, 0.0)
    # P0: x1 as ekf_pat's clipped prior (2 V), d 5 deg, drift 0.1 deg per step
    P0: tuple[float, ...] = (4.0, 25.0, 25.0, 0.01, 0.01)
    # Q per nominal step: Table I's Q_sys for x1 and each pointing axis, a slow drift walk
    Q: tuple[float, ...] = (0.0025, 0.01, 0.01, 1e-6, 1e-6)
    noise: float = 0.2                # sigma of v (V): R = sigma^2
    gain: float = 0.5                 # G of the P law (21), per axis
    feedforward: bool = True          # add vhat to u (not in the paper)
    dt: float = PAPER_DT
    x1_floor: float = 0.05            # x1hat is kept >= this (Section IV assumes x1 > 0)

    def __post_init__(self) -> None:
        """Check every parameter; raise AlignmentError with the reason."""
        if len(self.x0) != 5 or len(self.P0) != 5 or len(self.Q) != 5:
            raise AlignmentError(f'x0, P0 and Q need 5 entries ({", ".join(STATES)})')
        values = (self.radius, self.noise, self.gain, self.dt, self.x1_floor,
                  *self.x0, *self.P0, *self.Q)
        if not all(math.isfinite(v) for v in values):
            raise AlignmentError('every conical-scan EKF parameter must be finite')
        if min(self.P0) < 0.0 or min(self.Q) < 0.0:
            raise AlignmentError('P0 and Q must be >= 0')
        if not self.noise > 0.0:
            raise AlignmentError(f'noise must be > 0 V, got {self.noise}')
        if not 0.0 < self.gain < 2.0:
            raise AlignmentError(f'gain G must be in (0, 2) (u = -G dhat), got {self.gain}')
        if not self.dt > 0.0:
            raise AlignmentError(f'dt must be > 0 s, got {self.dt}')


def transition(mu: float) -> FloatArray:
    """F over mu nominal steps: d <- d - mu v, x1 and v constant."""
    F = np.eye(5)
    F[1, 3] = F[2, 4] = -mu
    return F


class ConicalScanEKF:
    """
    The conical-scan EKF and its P controller, vectorised over runs.

    `step(stamp, z)` predicts over the time since the previous call, updates with z
    (NaN/None: missing), and returns the tangent-plane turn (runs, 2) to send.
    """

    states = STATES

    def __init__(self, config: ConicalEKFConfig = ConicalEKFConfig(),
                 response: Optional[RadialResponse] = None, *, runs: int = 1) -> None:
        self.config = config
        self.response = response if response is not None else RadialResponse(IncidenceResponse())
        self.runs = int(runs)
        if self.runs < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self.scan = conical_scan(config.radius, config.points)
        self.Q = np.diag(np.asarray(config.Q, dtype=float))
        self.R = np.full((self.runs, 1, 1), config.noise ** 2)
        n = self.runs
        self.x = np.tile(np.asarray(config.x0, dtype=float), (n, 1))
        self.P = np.tile(np.diag(np.asarray(config.P0, dtype=float)), (n, 1, 1))
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.index = 0                               # s_k = scan[index]
        self.clock = StampClock(config.dt)
        self.u = np.zeros((n, 2))                    # u_{k-1}, not yet predicted over
        self.y = np.zeros(n)                         # innovation of the last update
        self.S = np.full(n, np.nan)                  # its variance
        self.updated: NDArray[np.bool_] = np.zeros(n, dtype=bool)

    @property
    def scan_offset(self) -> FloatArray:
        """s_k, the tangent-plane offset (2,) at which the next sample is taken."""
        return self.scan[self.index]

    def predict(self, mu: float) -> None:
        """Predict over mu nominal steps: x <- F x + B u_{k-1}, P <- F P F^T + mu Q."""
        Bu = np.zeros((self.runs, 5))
        Bu[:, 1:3] = self.u
        self.x, self.P = kalman.predict_batch(self.x, np.ascontiguousarray(self.P),
                                              transition(mu), mu * self.Q, Bu)
        self.u = np.zeros((self.runs, 2))
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def h(self, x: FloatArray, offset: FloatArray) -> FloatArray:
        """Return the predicted sample x1 g_r(|d + s|), one per run."""
        e = x[:, 1:3] + offset
        return x[:, 0] * self.response.g(np.hypot(e[:, 0], e[:, 1]))

    def jacobian(self, x: FloatArray, offset: FloatArray) -> FloatArray:
        """H = dh/dx (runs, 1, 5): [g_r, x1 g_r'/theta (d + s), 0, 0]."""
        e = x[:, 1:3] + offset
        H = np.zeros((x.shape[0], 1, 5))
        H[:, 0, 0] = self.response.g(np.hypot(e[:, 0], e[:, 1]))
        H[:, 0, 1:3] = x[:, 0, None] * self.response.gradient(e)
        return H

    def update(self, z: FloatArray) -> None:
        """Run the EKF update for the runs whose z is finite, linearised at the prior."""
        have = np.isfinite(z)
        offset = self.scan_offset
        H = self.jacobian(self.x, offset)
        hx = self.h(self.x, offset)
        # H x + d = h(x) at the prior: d = h(x) - H x
        d = (hx - (H @ self.x[:, :, None])[:, 0, 0])[:, None]
        zz = np.where(have, z, hx)[:, None]
        self.y = np.where(have, z - hx, 0.0)
        self.S = (H @ self.P @ H.transpose(0, 2, 1))[:, 0, 0] + self.R[:, 0, 0]
        x_post, P_post = kalman.update_batch(self.x, np.ascontiguousarray(self.P), zz, H,
                                             self.R, d)
        self.x = np.where(have[:, None], x_post, self.x)
        self.P = np.where(have[:, None, None], P_post, self.P)
        self.x[:, 0] = np.maximum(self.x[:, 0], self.config.x1_floor)
        self.updated = have

    def control(self) -> FloatArray:
        """u_k = -G dhat_k (+ vhat_k with feedforward), per axis."""
        u = -self.config.gain * self.x[:, 1:3]
        if self.config.feedforward:
            u = u + self.x[:, 3:5]
        return u

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """One sample at `stamp`: predict, update, control; return the turn (runs, 2)."""
        z = as_measurement(z, self.runs)
        mu = self.clock.tick(stamp)
        if mu is not None:
            self.predict(mu)
        self.update(z)
        u = self.control()
        self.u = u
        s_now = self.scan_offset
        self.index = (self.index + 1) % len(self.scan)
        return u + self.scan_offset - s_now

    def correct_last_turn(self, delta: FloatArray) -> None:
        """Account for a mount that turned delta (runs, 2) more than commanded (clamped)."""
        self.u = self.u + np.asarray(delta, dtype=float)

    def restart_runs(self, mask: NDArray[np.bool_], x: FloatArray, P: FloatArray) -> None:
        """Start the runs in mask afresh from x (m, 5) and P (m, 5, 5); their next turn is 0."""
        self.x[mask] = x
        self.P[mask] = P
        self.u[mask] = 0.0
