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
The closed-loop tracking simulation of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018).

Eq. (25): x1_k = x1_{k-1} + w1, x2_k = x2_{k-1} + beta + u_{k-1} + w2, with Table I's
parameters, and the tracking percentages of Section V (Table I, Fig. 8-10).
"""

import dataclasses
from dataclasses import dataclass
import math
from typing import Collection, Optional, Sequence

import numpy as np

from tskf_ros.led.intensity_model import (AlignmentError, FloatArray, IncidenceResponse,
                                          MAX_INTENSITY, TRACKING_ANGLE, TRACKING_LEVEL,
                                          wrap_degrees)
from tskf_ros.led.lqg_alignment import LQGAligner
from tskf_ros.led.scanning_ekf import Aligner, PAPER_DT, PAPER_Q_SYS, ScanningEKF


@dataclass(frozen=True)
class TrackingLinkConfig:
    """
    The simulated link of Section V: eq. (25) with Table I's system noise.

    beta is the transmitter's angular rate in degrees per second, added as beta * dt per
    step; Q_sys is per step.  noise is the standard deviation of v in volts (R_sys = 0.04
    is noise 0.2).  x1 starts where the peak intensity is `max_intensity`, and x2 (the
    scan mean, or the orientation for the baselines) at x2_0 degrees, or (not in the
    paper: a cold start) uniform on x2_0 +- x2_0_spread, drawn after all other noise.
    dropout is the probability that a measurement is missing (Bernoulli, independent per
    step and run).  blocked: a time interval [start, stop) s in which no light arrives
    (the clean intensity is 0), not in the paper.
    """

    beta: float = 1.2
    dt: float = PAPER_DT
    steps: int = 400
    noise: float = 0.2
    q_sys: tuple[float, float] = (PAPER_Q_SYS[0][0], PAPER_Q_SYS[1][1])
    max_intensity: float = MAX_INTENSITY
    x2_0: float = 5.0
    dropout: float = 0.0
    x2_0_spread: float = 0.0
    blocked: tuple[float, ...] = ()     # s: [start, stop) with no light (not in the paper)


@dataclass
class Trajectory:
    """
    One simulation: time (steps,) and per-step, per-run arrays (steps, runs).

    A field the simulation was asked not to keep (simulate_blocks' `keep`) has no steps:
    (0, runs), and no estimate (None).
    """

    t: FloatArray
    phi: FloatArray        # true angle of incidence, unwrapped (degrees)
    x2: FloatArray         # true scan mean phi - psi_k (the baselines: phi)
    x1: FloatArray         # true intensity factor
    clean: FloatArray      # x1 g(phi), the clean measurement (V)
    z: FloatArray          # the measurement given to the aligner, NaN when missing
    command: FloatArray    # motor command returned by the aligner
    estimate: Optional[FloatArray] = None   # (steps, runs, 2) posterior [x1, x2], EKFs


# the per-step fields of a Trajectory
FIELDS = ('phi', 'x2', 'x1', 'clean', 'z', 'command', 'estimate')


@dataclass(frozen=True)
class Disturbances:
    """
    The random numbers of one simulation (steps, runs), in the order they are drawn.

    v is standard normal: a link's noise scales it at each step, so links that differ in
    noise (and in dropout: u < dropout is missing) share these numbers.
    """

    w1: FloatArray         # w1 of eq. (25), N(0, Q_sys,11)
    w2: FloatArray         # w2 of eq. (25), N(0, Q_sys,22)
    v: FloatArray          # v of eq. (8) over the link's noise, N(0, 1)
    u: FloatArray          # uniform on [0, 1): the measurement is missing where u < dropout
    x2_0: FloatArray       # (runs,): the true x2 at the start (deg)

    @property
    def runs(self) -> int:
        """Return the number of runs."""
        return int(self.w1.shape[1])


def draw_disturbances(link: TrackingLinkConfig, rng: np.random.Generator,
                      runs: int) -> Disturbances:
    """Draw the noise of `runs` runs of link.steps steps (w1, w2, v, dropouts, then x2_0)."""
    n, steps = int(runs), int(link.steps)
    w1 = rng.standard_normal((steps, n)) * math.sqrt(link.q_sys[0])
    w2 = rng.standard_normal((steps, n)) * math.sqrt(link.q_sys[1])
    v = rng.standard_normal((steps, n))
    u = rng.random((steps, n))
    x2_0 = np.full(n, link.x2_0)
    if link.x2_0_spread > 0.0:
        x2_0 = x2_0 + rng.uniform(-link.x2_0_spread, link.x2_0_spread, n)
    return Disturbances(w1=w1, w2=w2, v=v, u=u, x2_0=x2_0)


@dataclass(frozen=True)
class Block:
    """Runs side by side in one simulation: their link and their noise."""

    link: TrackingLinkConfig
    noise: Disturbances


def _check(link: TrackingLinkConfig) -> None:
    if int(link.steps) < 1:
        raise AlignmentError(f'steps must be at least 1, got {int(link.steps)}')
    if not 0.0 <= link.dropout < 1.0:
        raise AlignmentError(f'dropout must be in [0, 1), got {link.dropout}')


def simulate_tracking(aligner: Aligner, link: TrackingLinkConfig, rng: np.random.Generator,
                      response: Optional[IncidenceResponse] = None) -> Trajectory:
    """
    Run the aligner in closed loop with eq. (25) for link.steps steps.

    Step k: the receiver at phi_k measures z_k = x1_k g(phi_k) + v_k (eq. (8)), the aligner
    returns the command c_k, and phi_{k+1} = phi_k + beta dt + c_k + w2, x1_{k+1} =
    |x1_k + w1| (kept positive, as Section IV assumes).  The noise is drawn up front in a
    fixed order (`draw_disturbances`), so aligners run with the same seed see the same w,
    v and dropouts.
    """
    _check(link)
    noise = draw_disturbances(link, rng, aligner.runs)
    return simulate_blocks(aligner, [Block(link, noise)], response)


def simulate_blocks(aligner: Aligner, blocks: Sequence[Block],
                    response: Optional[IncidenceResponse] = None, *,
                    keep: Collection[str] = FIELDS) -> Trajectory:
    """
    Run `simulate_tracking` on blocks of runs side by side: the aligner steps all at once.

    Block i's runs are the columns after those of blocks 0 .. i-1; its link gives their
    measurement noise, dropout and drift rate beta, its Disturbances their random numbers
    (blocks may share them: the same draws at several noise levels).  The links differ in
    noise, dropout and beta only.  Each run is what simulate_tracking gives it alone,
    number for number.  keep: the Trajectory fields recorded (FIELDS; the others have no
    steps: less memory).
    """
    response = response if response is not None else IncidenceResponse()
    if not blocks:
        raise AlignmentError('simulate_blocks needs at least one block of runs')
    link = blocks[0].link
    for b in blocks:
        _check(b.link)
        if dataclasses.replace(b.link, noise=link.noise, dropout=link.dropout,
                               beta=link.beta) != link:
            raise AlignmentError('the blocks of one simulation differ in noise, dropout and '
                                 'beta only')
    n, steps = aligner.runs, int(link.steps)
    sizes = [b.noise.runs for b in blocks]
    if sum(sizes) != n or any(b.noise.w1.shape[0] != steps for b in blocks):
        raise AlignmentError(f'the blocks hold {sum(sizes)} runs of '
                             f'{[b.noise.w1.shape[0] for b in blocks]} steps; the aligner has '
                             f'{n} runs, the link {steps} steps')

    def joined(name: str, k: int) -> FloatArray:
        """Row k of a noise array, the blocks side by side."""
        rows = [getattr(b.noise, name)[k] for b in blocks]
        return rows[0] if len(rows) == 1 else np.concatenate(rows)

    # each run's noise level and dropout probability
    noise = np.repeat([b.link.noise for b in blocks], sizes)
    dropout = np.repeat([b.link.dropout for b in blocks], sizes)
    t = np.arange(steps, dtype=float) * link.dt
    shape = (steps, n)
    unknown = set(keep) - set(FIELDS)
    if unknown:
        raise AlignmentError(f'keep: unknown fields {sorted(unknown)}; expected some of {FIELDS}')
    ekf = aligner if isinstance(aligner, (ScanningEKF, LQGAligner)) else None
    kept = {f: np.empty(shape if f in keep else (0, n)) for f in FIELDS if f != 'estimate'}
    estimate = None if ekf is None or 'estimate' not in keep else np.empty((steps, n, 2))
    out = Trajectory(t=t, **kept, estimate=estimate)
    rows = [f for f in kept if f in keep]
    x1 = np.full(n, link.max_intensity / response.peak)
    phi = np.concatenate([b.noise.x2_0 for b in blocks]) + aligner.scan_offset
    # beta dt per run (one number when the blocks share beta)
    betas = {b.link.beta for b in blocks}
    drift = link.beta * link.dt if len(betas) == 1 else \
        np.repeat([b.link.beta for b in blocks], sizes) * link.dt
    for k in range(steps):
        clean = x1 * response.g(wrap_degrees(phi))
        if link.blocked and link.blocked[0] <= t[k] < link.blocked[1]:
            clean = np.zeros(n)
        # (8): V_d,k = x1 g(phi) + v_k
        z = np.where(joined('u', k) < dropout, np.nan, clean + joined('v', k) * noise)
        offset = aligner.scan_offset
        cmd = aligner.step(t[k], z)
        now = {'phi': phi, 'x1': x1, 'clean': clean, 'z': z, 'command': cmd}
        for f in rows:
            kept[f][k] = now[f] if f != 'x2' else phi - offset
        if ekf is not None and estimate is not None:
            estimate[k] = ekf.x[:, :2]
        # (25): x2_k = x2_{k-1} + beta + u_{k-1} + w2 (here on phi = x2 + psi, with the scan)
        phi = phi + drift + cmd + joined('w2', k)
        x1 = np.abs(x1 + joined('w1', k))
    return out


def tracking(traj: Trajectory, *, angle: float = TRACKING_ANGLE,
             threshold: float = TRACKING_LEVEL * MAX_INTENSITY) -> tuple[FloatArray, FloatArray]:
    """Tracking percentage per run (Section V): by angle |phi| <= 15 deg, by clean >= 0.6 V."""
    angular = 100.0 * np.mean(np.abs(wrap_degrees(traj.phi)) <= angle, axis=0)
    measure = 100.0 * np.mean(traj.clean >= threshold, axis=0)
    return angular, measure
