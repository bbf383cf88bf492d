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
The scanning EKF of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018), Section IV.

State (6) x = [x1, x2] = [C_p I_theta e^{-cd} / d^2, mean receiver angle of the scan],
dynamics (7)/(10) x_k = A x_{k-1} + B u_{k-1} + w_{k-1} with A = I, B = [0, 1]^T (9).
The receiver scans through Psi (Section IV, Fig. 7), and the EKF of eq. (13)-(20) uses
the last two measurements (12), y_k = [x1 g(x2_k + psi_k), x1 g(x2_{k-1} + psi_{k-1})].
The P controller (21) u_k = -G x2hat_k drives the scan mean to zero and the motor gets
u_k + psi_{k+1} - psi_k.  Observability (Section IV, det C_k != 0) is checked when the
filter is made (led/scan_observability.py, with where the paper's eq. (24) is read the
other way).

Not in the paper: a gap of missing measurements is predicted over with mu = elapsed / dt
(P^f = P + mu Q), and every aligner is vectorised over independent runs
(doc/design/alignment.md).
"""

from dataclasses import dataclass
import math
from typing import Optional, Protocol, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import kalman
from tskf_ros.led.intensity_model import AlignmentError, FloatArray, IncidenceResponse
from tskf_ros.led.scan_observability import observability, SCAN_ANGLES

# one measurement per run (a float for every run, NaN or None: missing)
Measurement = Union[None, float, Sequence[float], FloatArray]
# a matrix written as rows, as in Table I
Rows = tuple[tuple[float, ...], ...]

# Table I.
PAPER_X0 = (2.0, 0.0)
PAPER_P0 = ((100.0, 0.0), (0.0, 1000.0))
PAPER_Q_SYS = ((0.0025, 0.0), (0.0, 0.01))
PAPER_Q = ((0.25, 0.0), (0.0, 1.0))
PAPER_R_SYS = ((0.04, 0.0), (0.0, 0.04))
PAPER_R = ((1.0, 0.0), (0.0, 1.0))
PAPER_GAIN = 0.5
PAPER_DT = 0.05                 # s per iteration (Section VI: about 50 ms per EKF step)


class Aligner(Protocol):
    """What the tracking simulation needs from an alignment algorithm."""

    runs: int

    @property
    def scan_offset(self) -> float:
        """Offset of the receiver from its mean angle at the next step (degrees)."""

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Take the measurement at `stamp` (NaN/None: missing); return the motor commands."""


def as_measurement(z: Measurement, runs: int) -> FloatArray:
    """Return one float per run; None and non-finite entries become NaN (missing)."""
    if z is None:
        return np.full(runs, np.nan)
    arr = np.array(z, dtype=float).reshape(-1)
    if arr.size == 1 and runs > 1:
        arr = np.full(runs, arr[0])
    if arr.size != runs:
        raise AlignmentError(f'expected {runs} measurements, got {arr.size}')
    arr[~np.isfinite(arr)] = np.nan
    return arr


# nominal steps: the longest gap a filter predicts over (1600 years at 50 ms).  Its state
# and covariance stay finite to about 1e150 steps; beyond, mu^2 P overflows into NaN
MAX_MU = 1e12


class StampClock:
    """Stamps of the calls: rejects stale ones and gives mu = elapsed / dt."""

    def __init__(self, dt: float) -> None:
        if not (math.isfinite(dt) and dt > 0.0):
            raise AlignmentError(f'dt must be positive, got {dt}')
        self.dt = float(dt)
        self.stamp: Optional[float] = None

    def tick(self, stamp: float) -> Optional[float]:
        """Advance to stamp; return mu (None at the first call)."""
        stamp = float(stamp)
        if not math.isfinite(stamp):
            raise AlignmentError(f'stamp must be finite, got {stamp}')
        if self.stamp is None:
            self.stamp = stamp
            return None
        if stamp <= self.stamp:
            raise AlignmentError(f'stale stamp {stamp!r}: not after the previous one '
                                 f'{self.stamp!r}')
        mu = (stamp - self.stamp) / self.dt
        if mu > MAX_MU:
            raise AlignmentError(f'a gap of {stamp - self.stamp:.3g} s is {mu:.3g} nominal '
                                 f'steps, beyond the {MAX_MU:.0e} a filter predicts over')
        self.stamp = stamp
        return mu


@dataclass(frozen=True)
class EKFConfig:
    """The scanning EKF's parameters (Table I defaults)."""

    x0: tuple[float, ...] = PAPER_X0
    P0: Rows = PAPER_P0
    Q: Rows = PAPER_Q
    R: Rows = PAPER_R
    gain: float = PAPER_GAIN
    scan: tuple[float, ...] = SCAN_ANGLES
    dt: float = PAPER_DT
    # Not in the paper: project x1hat onto [x1_floor, inf) after each update, enforcing
    # Section IV's assumption x1hat > 0 (None: the paper's unconstrained EKF).
    x1_floor: Optional[float] = None


class ScanningEKF:
    """
    The EKF-based alignment of Section IV, eq. (13)-(21), vectorised over runs.

    Each `step(stamp, z)` is one iteration k: predict (13)-(14) over the time since the
    previous call, update with the measurement pair (12) if z_k arrived, compute the
    control (21) and return the motor command u_k + psi_{k+1} - psi_k.  Posterior
    x, P and prior x_prior, P_prior have a leading runs axis.  R is config.R, shared by
    every run, or a stack (runs, 2, 2) of one R per run (runs at several noise levels).
    """

    def __init__(self, config: EKFConfig = EKFConfig(),
                 response: Optional[IncidenceResponse] = None, *, runs: int = 1) -> None:
        self.response = response if response is not None else IncidenceResponse()
        observability(config.gain, config.scan, self.response)
        self.config = config
        self.runs = int(runs)
        if self.runs < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self.scan = np.asarray(config.scan, dtype=float)
        self.gain = float(config.gain)
        self.Q = np.asarray(config.Q, dtype=float).reshape(2, 2)
        self.R = np.asarray(config.R, dtype=float).reshape(2, 2)
        x0 = np.asarray(config.x0, dtype=float).reshape(2)
        P0 = np.asarray(config.P0, dtype=float).reshape(2, 2)
        n = self.runs
        # Table I gives the first forecast: xhat_0 and P_0^f.
        self.x = np.tile(x0, (n, 1))
        self.P = np.tile(P0, (n, 1, 1))
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()
        self.index = 0                           # k mod len(Psi): psi_k = scan[index]
        self.clock = StampClock(config.dt)
        self.u = np.zeros(n)                     # u_{k-1}, not yet in the prediction
        self.since = np.zeros(n)                 # sum of u applied since the last z
        self.z_prev = np.full(n, np.nan)         # last measurement that arrived
        self.psi_prev = np.zeros(n)              # the scan angle it was taken at
        self.y = np.zeros((n, 2))                # residual y_k - yhat_k
        self.C = np.zeros((n, 2, 2))             # C_k of (17)
        self.det = np.full(n, np.nan)            # |C_k|, NaN without a pair
        self.singular: NDArray[np.bool_] = np.zeros(n, dtype=bool)
        self.updated: NDArray[np.bool_] = np.zeros(n, dtype=bool)
        self.det_tolerance = 1e-9

    @property
    def scan_offset(self) -> float:
        """psi_k, the scan angle at which the next measurement is taken."""
        return float(self.scan[self.index])

    def predict(self, mu: float = 1.0) -> None:
        """Eq. (13)-(14) over mu nominal steps (mu = elapsed / dt, the graininess)."""
        # (13): x1^f = x1, x2^f = x2 + u_{k-1}
        self.x[:, 1] += self.u
        # (14): P^f = A P A^T + mu Q with A = I (Q is per nominal step, so it scales with mu)
        self.P = self.P + mu * self.Q
        self.u = np.zeros(self.runs)
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()

    def linearise(self, x: FloatArray, psi: float, shift: FloatArray,
                  psi_prev: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return h(x) of eq. (16) and its Jacobian C_k of eq. (17) at x (g evaluated once)."""
        a1 = x[:, 1] + psi
        a2 = x[:, 1] - shift + psi_prev
        g1, dg1 = self.response.g_dg(a1)
        g2, dg2 = self.response.g_dg(a2)
        # (16): [x1 g(x2 + psi_k), x1 g(x2 - shift + psi_{k-1})], shift = u since z_prev.
        # (15) prints x1hat_{k-1}^f in row 2 but (17) differentiates it with respect to
        # x1hat_k^f; under (7) x1 has no input, so both rows use the current x1.
        hx = np.stack([x[:, 0] * g1, x[:, 0] * g2], axis=-1)
        C = np.empty((x.shape[0], 2, 2))
        C[:, 0, 0] = g1                    # C_k,1,1 = g(x2^f + psi_k)
        C[:, 0, 1] = x[:, 0] * dg1         # C_k,1,2 = x1^f g'(x2^f + psi_k)
        C[:, 1, 0] = g2                    # C_k,2,1 = g(x2^f - u_{k-1} + psi_{k-1})
        C[:, 1, 1] = x[:, 0] * dg2         # C_k,2,2 = x1^f g'(x2^f - u_{k-1} + psi_{k-1})
        return hx, C

    def h(self, x: FloatArray, psi: float, shift: FloatArray,
          psi_prev: FloatArray) -> FloatArray:
        """Eq. (16): [x1 g(x2 + psi_k), x1 g(x2 - shift + psi_{k-1})], shift = u since z_prev."""
        return self.linearise(x, psi, shift, psi_prev)[0]

    def jacobian(self, x: FloatArray, psi: float, shift: FloatArray,
                 psi_prev: FloatArray) -> FloatArray:
        """Eq. (17): C_k = dh/dx at x, one 2x2 matrix per run."""
        return self.linearise(x, psi, shift, psi_prev)[1]

    def update(self, z: FloatArray) -> None:
        """Eq. (18)-(20) for the runs whose z is finite; a run without z_prev uses row 1 only."""
        have = np.isfinite(z)
        pair = have & np.isfinite(self.z_prev)
        psi = self.scan_offset
        x, P = self.x, self.P
        # yhat_k = h(x^f) (15)-(16) and C_k (17)
        hx, C = self.linearise(x, psi, self.since, self.psi_prev)
        # y_k = [z_k, z_prev] (12)
        y = np.stack([np.where(have, z, 0.0), np.where(pair, self.z_prev, 0.0)], axis=-1)
        y = y - hx
        # the first measurement has no partner: drop row 2 (zero row and residual)
        C[~pair, 1, :] = 0.0
        y[~pair, 1] = 0.0
        y[~have] = 0.0
        self.C = C
        self.y = y
        # |C_k| of each run's 2 x 2 C_k, written out (numpy's det of a stack factorises each)
        self.det = np.where(pair, C[:, 0, 0] * C[:, 1, 1] - C[:, 0, 1] * C[:, 1, 0], np.nan)
        scale = np.maximum(np.abs(x[:, 0]), 1e-12)
        self.singular = pair & (np.abs(self.det) <= self.det_tolerance * scale)
        # R as in Table I; z_prev was already used at the previous update, so the v's of
        # successive pairs are correlated, which the paper (and this filter) ignores.
        R = np.broadcast_to(self.R, C.shape).copy()
        R[~pair, 0, 1] = R[~pair, 1, 0] = 0.0
        # (18)-(20): the update of tskf_ros.core.kalman linearised at x^f: H = C_k and
        # H x + d = h(x^f), so its y is the residual above (zero in the dropped rows)
        d = hx - (C @ x[:, :, None])[:, :, 0]
        x_post, P_post = kalman.update_batch(x, np.ascontiguousarray(P), y + hx, C, R, d)
        self.x = np.where(have[:, None], x_post, x)
        self.P = np.where(have[:, None, None], P_post, P)
        if self.config.x1_floor is not None:
            self.x[:, 0] = np.maximum(self.x[:, 0], self.config.x1_floor)
        self.updated = have
        self.z_prev = np.where(have, z, self.z_prev)
        self.psi_prev = np.where(have, psi, self.psi_prev)
        self.since = np.where(have, 0.0, self.since)

    def innovation_distance(self, stamp: float, z: Measurement) -> FloatArray:
        """
        Return |z - yhat| / sqrt(S) of row 1 of (12) at the prior of `stamp`, per run.

        Not in the paper: the Mahalanobis distance of the new measurement alone against
        the prediction (13)-(14) over the time since the last call, with
        S = C_1 P^f C_1^T + R_11 and C_1 the first row of (17); nothing is changed.  For
        an innovation gate in front of `step`; NaN where z is missing.
        """
        z = as_measurement(z, self.runs)
        last = self.clock.stamp
        mu = 0.0 if last is None else max(float(stamp) - last, 0.0) / self.clock.dt
        x2 = self.x[:, 1] + (self.u if last is not None else 0.0)
        P = self.P + mu * self.Q
        a1 = x2 + self.scan_offset
        g, dg = self.response.g_dg(a1)
        C1 = np.stack([g, self.x[:, 0] * dg], axis=-1)
        S = np.einsum('ri,rij,rj->r', C1, P, C1) + self.R[..., 0, 0]
        with np.errstate(all='ignore'):
            return np.abs(z - self.x[:, 0] * g) / np.sqrt(S)

    def correct_last_turn(self, delta: FloatArray) -> None:
        """Account for a base that turned delta more than commanded (clamped): u_k += delta."""
        self.u = self.u + delta
        self.since = self.since + delta

    def restart_runs(self, mask: NDArray[np.bool_], x: FloatArray, P: FloatArray) -> None:
        """
        Start the runs in mask afresh from the forecast x (m, 2) and P (m, 2, 2).

        Not in the paper: for a supervisor that hands over from a search or resets after a
        loss; x and P are what the next step predicts from (its turn u is 0), and the
        first update has no partner measurement.
        """
        self.x[mask] = x
        self.P[mask] = P
        self.u[mask] = 0.0
        self.since[mask] = 0.0
        self.z_prev[mask] = np.nan
        self.psi_prev[mask] = 0.0

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """Run one iteration at `stamp` with z_k (NaN/None: missing); return the commands."""
        z = as_measurement(z, self.runs)
        mu = self.clock.tick(stamp)
        if mu is not None:
            self.predict(mu)
        self.update(z)
        # (21): u_k = -G x2hat_k
        u = -self.gain * self.x[:, 1]
        self.u = u
        self.since = self.since + u
        psi = self.scan_offset
        self.index = (self.index + 1) % len(self.scan)
        # motor command u_k + psi_{k+1} - psi_k
        return u + self.scan_offset - psi
