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
LQG alignment: a scanning EKF that estimates the drift, and the time-scale LQR (8).

The scanning EKF of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018) with the drift rate
estimated, and the LQR of Bohner & Wintz (J. Math. Anal. Appl. 2013), by certainty
equivalence (their Remark 4.2).

State x = [x1, x2, b]: Solanki's (6) plus b, the drift of x2 per nominal step (beta dt of
eq. (25)), on the time scale of the calls (mu = elapsed / dt):

    x1^sigma = x1 + w1,   x2^sigma = x2 + mu b + turn + w2,   b^sigma = b + w_b
    z_k = x1 g(x2 + psi_k) + v_k                                       (8), (12) row 1

The EKF (tskf_ros.core.kalman) takes one measurement per step.  During the acquisition
scan it is a bank of EKFs started at several x2 (a Gaussian sum, weights by the
innovation likelihood N(e; 0, S)); at its end each run keeps its most likely member.
The control is a turn per step: turn = mu (v - bhat) with v = -L(mu) x2hat, L the
stationary gain (8) of the sweep (7) for x2^Delta = v (the drift cancelled by
feed-forward; Remark 4.2's u = -L xhat), and the motor gets turn + psi_{k+1} - psi_k,
kept at least `min_motion` from 0, so that two successive measurements are never
taken at one angle (the singular case of eq. (22)-(23)).  Choices, numbers:
doc/design/lqr.md.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import kalman
from tskf_ros.core.lqr import TimeScaleLQR
from tskf_ros.led.intensity_model import AlignmentError, IncidenceResponse
from tskf_ros.led.scanning_ekf import (as_measurement, Measurement, PAPER_DT, SCAN_ANGLES,
                                       StampClock)

Array = NDArray[np.float64]


def triangle_scan(amplitude: float, step: float = 2.0) -> tuple[float, ...]:
    """Return Solanki's scan (Fig. 7) for another amplitude: -step, ..., -amplitude, ..., 0."""
    if not (math.isfinite(amplitude) and math.isfinite(step) and 0 < step <= amplitude):
        raise AlignmentError(f'the scan needs 0 < step <= amplitude, got step {step:g}, '
                             f'amplitude {amplitude:g}')
    count = int(round(amplitude / step))
    if not math.isclose(count * step, amplitude, rel_tol=1e-9):
        raise AlignmentError(f'amplitude {amplitude:g} is not a multiple of the step {step:g}')
    up = [step * i for i in range(1, count + 1)]
    half = up + up[-2::-1] + [0.0]
    return tuple([-a for a in half] + half)


def lqr_turn(L: float, mu: float, error: Array, drift: Array) -> Array:
    """
    Return the turn over a step of graininess mu: mu (v - bhat), v = -L xhat.

    u = -L xhat is Remark 4.2's certainty-equivalent control of the error xhat, and the
    estimated drift bhat of the error per nominal step (x^sigma = x + mu b + turn) is
    cancelled over the step; error and drift broadcast (one axis or two).
    """
    return mu * (-L * error - drift)


@dataclass(frozen=True)
class LQGConfig:
    """
    The LQG aligner's parameters (angles in degrees, rates per nominal step dt).

    x0, P0: the prior of [x1, x2, b] (a diagonal P0); x2_starts: the x2 of the bank's
    members during the acquisition (each with variance P0[1]).  Q (per nominal step) and
    R (V^2) are the EKF's noise model; state_weight and input_weight the weights of x2
    and of the turn rate v in the cost (4).  acquisition: the scan angles visited once
    first; scan: the angles visited cyclically after.
    """

    x0: tuple = (2.0, 0.0, 0.0)
    P0: tuple = (1.0, 4.0, 0.1)
    x2_starts: tuple = (-16.0, -12.0, -8.0, -4.0, 0.0, 4.0, 8.0, 12.0, 16.0)
    Q: tuple = (0.0025, 0.01, 1e-5)
    R: float = 1.0
    state_weight: float = 0.25
    input_weight: float = 2.0
    acquisition: tuple = SCAN_ANGLES * 2
    scan: tuple = triangle_scan(4.0)
    dt: float = PAPER_DT
    min_motion: float = 0.5


class LQGAligner:
    """
    The LQG alignment controller, vectorised over runs like ScanningEKF.

    `step(stamp, z)`: predict over the time since the last call, update with z (NaN or
    None: missing), and return the motor command per run.  x, P are the posterior of
    the most likely member (runs axis first); x_prior, P_prior the prediction before the
    last update; `regulator` is the scalar TimeScaleLQR of x2.
    """

    def __init__(self, config: LQGConfig = LQGConfig(),
                 response: Optional[IncidenceResponse] = None, *, runs: int = 1) -> None:
        self.config = config
        self.response = response if response is not None else IncidenceResponse()
        self.runs = int(runs)
        if self.runs < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self._check(config)
        self.scan = np.asarray(config.scan, dtype=float)
        self.acquisition = np.asarray(config.acquisition, dtype=float)
        self.Q = np.diag(np.asarray(config.Q, dtype=float))
        self.regulator = TimeScaleLQR(0.0, 1.0, config.state_weight, config.input_weight)
        starts = np.asarray(config.x2_starts if self.acquisition.size else (), dtype=float)
        members = max(starts.size, 1)
        x0 = np.tile(np.asarray(config.x0, dtype=float), (self.runs, members, 1))
        if starts.size:
            x0[:, :, 1] = starts
        self._x = x0
        self._P = np.tile(np.diag(np.asarray(config.P0, dtype=float)),
                          (self.runs, members, 1, 1))
        self.log_weight = np.zeros((self.runs, members))
        self.x_prior, self.P_prior = self.x, self.P
        self.index = 0                      # k: psi_k = scan_offset
        self.clock = StampClock(config.dt)
        self.mu = 1.0                       # the expected graininess: the last one seen
        self.turn = np.zeros(self.runs)     # the last turn, not yet in the prediction

    @staticmethod
    def _check(config: LQGConfig) -> None:
        for name, size in (('x0', 3), ('P0', 3), ('Q', 3)):
            v = np.asarray(getattr(config, name), dtype=float)
            if v.shape != (size,) or not np.all(np.isfinite(v)):
                raise AlignmentError(f'{name} must be {size} finite numbers, got '
                                     f'{getattr(config, name)}')
            if name != 'x0' and np.any(v < 0):
                raise AlignmentError(f'{name} must be >= 0 (a diagonal), got {v.tolist()}')
        if not np.all(np.asarray(config.P0) > 0):
            raise AlignmentError(f'P0 must be > 0, got {config.P0}')
        scan = np.asarray(config.scan, dtype=float)
        if scan.ndim != 1 or scan.size < 2 or not np.all(np.isfinite(scan)):
            raise AlignmentError(f'the scan needs at least two finite angles, got {config.scan}')
        if not np.all(np.isfinite(np.asarray(config.acquisition, dtype=float))):
            raise AlignmentError('the acquisition scan has non-finite angles')
        if not np.all(np.isfinite(np.asarray(config.x2_starts, dtype=float))):
            raise AlignmentError('x2_starts has non-finite angles')
        for name in ('R', 'state_weight', 'input_weight', 'dt'):
            value = float(getattr(config, name))
            if not (math.isfinite(value) and value > 0):
                raise AlignmentError(f'{name} must be > 0, got {value}')
        if not (math.isfinite(config.min_motion) and config.min_motion >= 0):
            raise AlignmentError(f'min_motion must be >= 0, got {config.min_motion}')

    @property
    def members(self) -> int:
        """Return the number of members of the EKF bank per run (1 after the acquisition)."""
        return int(self._x.shape[1])

    @property
    def x(self) -> Array:
        """Return the most likely member's posterior [x1, x2, b] per run."""
        return self._x[np.arange(self.runs), np.argmax(self.log_weight, axis=1)]

    @property
    def P(self) -> Array:
        """Return the most likely member's posterior covariance per run."""
        return self._P[np.arange(self.runs), np.argmax(self.log_weight, axis=1)]

    @property
    def scan_offset(self) -> float:
        """psi_k, the scan angle at which the next measurement is taken."""
        k = self.index
        if k < self.acquisition.size:
            return float(self.acquisition[k])
        return float(self.scan[(k - self.acquisition.size) % self.scan.size])

    def predict(self, mu: float) -> None:
        """x(sigma) = F x + [0, turn, 0], P(sigma) = F P F^T + mu Q, F = I + mu A."""
        F = np.eye(3)
        F[1, 2] = mu                        # x2^sigma = x2 + mu b
        n = self.runs * self.members
        Bu = np.zeros((self.runs, self.members, 3))
        Bu[:, :, 1] = self.turn[:, None]
        x, P = kalman.predict_batch(self._x.reshape(n, 3), self._P.reshape(n, 3, 3), F,
                                    mu * self.Q, Bu.reshape(n, 3))
        self._x, self._P = x.reshape(self._x.shape), P.reshape(self._P.shape)
        self.turn = np.zeros(self.runs)

    def update(self, z: Array) -> None:
        """Run the EKF update with z_k = x1 g(x2 + psi_k) + v for the runs whose z is finite."""
        runs, m = self.runs, self.members
        have = np.repeat(np.isfinite(z), m)
        x, P = self._x.reshape(-1, 3), self._P.reshape(-1, 3, 3)
        a = x[:, 1] + self.scan_offset
        g, dg = self.response.g(a), self.response.dg(a)
        H = np.zeros((x.shape[0], 1, 3))
        H[:, 0, 0] = g                      # dh/dx1 = g(x2 + psi)
        H[:, 0, 1] = x[:, 0] * dg           # dh/dx2 = x1 g'(x2 + psi)
        hx = x[:, 0] * g
        # linearised at the prior: h(x) ~ h(x^f) + H (x - x^f), so d = h(x^f) - H x^f
        d = hx - np.einsum('ri,ri->r', H[:, 0, :], x)
        zz = np.where(have, np.repeat(z, m), hx)
        R = np.full((x.shape[0], 1, 1), float(self.config.R))
        x_post, P_post = kalman.update_batch(x, np.ascontiguousarray(P), zz[:, None], H, R,
                                             d[:, None])
        if m > 1:
            # the bank's weights: log N(e; 0, S), S = H P H^T + R, for the innovation e
            S = np.einsum('ri,rij,rj->r', H[:, 0, :], P, H[:, 0, :]) + self.config.R
            e = zz - hx
            ll = np.where(have, -0.5 * (e * e / S + np.log(S)), 0.0).reshape(runs, m)
            self.log_weight = self.log_weight + ll
            self.log_weight -= self.log_weight.max(axis=1, keepdims=True)
        self._x = np.where(have[:, None], x_post, x).reshape(self._x.shape)
        self._P = np.where(have[:, None, None], P_post, P).reshape(self._P.shape)

    def _collapse(self) -> None:
        """Keep each run's most likely member (the end of the acquisition)."""
        self._x, self._P = self.x[:, None, :], self.P[:, None, :, :]
        self.log_weight = np.zeros((self.runs, 1))

    def control(self) -> Array:
        """Return the turn mu (v - bhat), v = -L(mu) x2hat, at the expected graininess mu."""
        mu = self.mu
        L = float(self.regulator.stationary(mu).L[0, 0])
        x = self.x
        return lqr_turn(L, mu, x[:, 1], x[:, 2])

    def correct_last_turn(self, delta: Array) -> None:
        """Account for a base that turned delta more than commanded (clamped)."""
        self.turn = self.turn + delta

    def step(self, stamp: float, z: Measurement) -> Array:
        """Run one iteration at `stamp` with z_k (NaN/None: missing); return the commands."""
        z = as_measurement(z, self.runs)
        mu = self.clock.tick(stamp)
        if mu is not None:
            self.predict(mu)
            self.mu = mu
        self.x_prior, self.P_prior = self.x, self.P
        self.update(z)
        turn = self.control()
        psi = self.scan_offset
        self.index += 1
        if self.index == self.acquisition.size and self.members > 1:
            self._collapse()
        dpsi = self.scan_offset - psi
        command = turn + dpsi
        # never the same angle twice (eq. (22)-(23)): |command| >= min_motion
        small = np.abs(command) < self.config.min_motion
        if small.any():
            side = np.where(command != 0.0, np.sign(command), 1.0 if dpsi >= 0 else -1.0)
            command = np.where(small, side * self.config.min_motion, command)
        self.turn = command - dpsi
        return command
