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
Section IV, eq. (7)-(21)) with the drift states of lqg_alignment; the geometry is in
`pointing_geometry`, the response in `radial_response`.  State, in the tangent plane at
the source (degrees, volts):

    x = [x1, d_c, d_e, b_c, b_e]

x1 the intensity factor of eq. (5)/(6), d the error of the mean pointing (the boresight
less the scan offset), b the drift of d per nominal step dt.  The receiver scans a circle
of radius r around its mean pointing, s_k = r [cos phi_k, sin phi_k] (`conical_scan`),
and each sample is

    z_k = h(x_k) + v_k = x1 g_r(|d_k + s_k|) + v_k,      R = sigma^2 + model_noise^2

(one scalar per sample, not the paper's pair (12): the scan's rotation makes d observable
over a turn, and the pair's reuse of z_{k-1} would correlate successive noises).  Over
mu = elapsed / dt nominal steps (mu from the stamps, as the time-scale filter):

    x1 <- x1,   d <- d + mu b + u_{k-1},   b <- b,   P <- F P F^T + mu Q

with u the turn of the mean pointing commanded at the previous sample.  The control,
per axis: 'p', the paper's P law (21) u_k = -G dhat_k, plus (not in the paper) the
estimated drift of one step, - bhat_k; or 'lqr', lqg_alignment's time-scale LQR
(Bohner & Wintz 2013, eq. (8)) u_k = mu (-L(mu) dhat_k - bhat_k) (lqg_alignment.lqr_turn).
The receiver is sent u_k and the scan's step to s_{k+1}, closed in joints at the mount's
tilt (pointing_geometry.closed_scan_turn).  Predict and update are tskf_ros.core.kalman's,
batched over independent runs; the update is that linear one with h linearised
(`linearise`): by its Jacobian (the EKF, the closed loop's), with its curvature (the
Gaussian second-order filter), or by a regression over sigma points (the unscented /
Gauss-Hermite filters, 3 or 5 points per axis), once or iterated (`update`).  CONSISTENT
is the configuration whose NEES is in its band at every noise level from 0 to 2.5 V.

The scan's own loss: with the mean pointing on the source the boresight is r off it, so
the scan costs 1 - g_r(r)/g_r(0) of the received intensity (`scan_loss`; 15 % at the
default r = 4 deg); with a mean error |d| the boresight is at most |d| + r off, so it
stays in the 15 deg tracking cone while |d| <= 15 - r.  With dim_radius > 0 (6.5 deg by
default, 34 % of the light on the source) each run's r widens towards dim_radius as its
x1hat g_r(0) falls from dim_peak to dim_peak / 2, and narrows back to `radius` at
dim_peak / 4 (`scan_radius.dim_scan_radius`: more information about d per sample, at a
larger loss).
"""

from typing import Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import kalman
from tskf_ros.core.lqr import TimeScaleLQR
from tskf_ros.led.intensity_model import AlignmentError, FloatArray
from tskf_ros.led.lqg_alignment import lqr_turn
from tskf_ros.led.scanning_ekf import as_measurement, Measurement, StampClock
from tskf_ros.led.two_axis.conical_ekf_config import (ConicalEKFConfig, CONSISTENT, CONTROLLERS,
                                                      LINEARISATIONS, MAX_SMOOTH_AFTER,
                                                      STATES)
from tskf_ros.led.two_axis.pointing_geometry import closed_scan_turn, conical_scan
from tskf_ros.led.two_axis.radial_response import RadialResponse
from tskf_ros.led.two_axis.scan_radius import dim_scan_radius
from tskf_ros.led.two_axis.sigma_points import regression
from tskf_ros.led.two_axis.window_smoother import Posterior, smooth_window, WindowRecord

# the parameters live in conical_ekf_config; they are imported from here as well
__all__ = ['CONSISTENT', 'ConicalEKFConfig', 'ConicalScanEKF', 'CONTROLLERS', 'LINEARISATIONS',
           'MAX_SMOOTH_AFTER', 'scan_loss', 'STATES', 'transition']


def scan_loss(radius: float, response: Optional[RadialResponse] = None) -> float:
    """Return 1 - g_r(r)/g_r(0): the intensity the scan alone costs, on the source."""
    response = response if response is not None else RadialResponse()
    return 1.0 - float(response.g(np.array([radius]))[0]) / response.peak


def transition(mu: float) -> FloatArray:
    """Return F over mu nominal steps: d <- d + mu b, x1 and b constant."""
    F = np.eye(5)
    F[1, 3] = F[2, 4] = mu
    return F


class ConicalScanEKF:
    """
    The conical-scan EKF and its P controller, vectorised over runs.

    `step(stamp, z)` predicts over the time since the previous call, updates with z
    (NaN/None: missing), and returns the tangent-plane turn (runs, 2) to send.
    """

    states = STATES

    def __init__(self, config: ConicalEKFConfig = ConicalEKFConfig(),
                 response: Optional[RadialResponse] = None, *, runs: int = 1,
                 tilt0: float = 20.0) -> None:
        self.config = config
        self.response = response if response is not None else RadialResponse()
        self.runs = int(runs)
        if self.runs < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self.scan = conical_scan(config.radius, config.points)
        self.unit_scan = conical_scan(1.0, config.points)
        self.radius = np.full(self.runs, config.radius)   # r per run (dim_radius)
        self.Q = np.diag(np.asarray(config.Q, dtype=float))
        # one R for every run (any subset of the runs can be updated: `smooth_window`)
        self.R = np.full((1, 1, 1), config.noise ** 2 + config.model_noise ** 2)
        n = self.runs
        self.x = np.tile(np.asarray(config.x0, dtype=float), (n, 1))
        self.P = np.tile(np.diag(np.asarray(config.P0, dtype=float)), (n, 1, 1))
        self.index = 0                               # s_k = scan[index]
        # x0's d is the boresight's error at the first sample (0: the receiver pointed at
        # the source); d is the mean pointing's, which is the scan's first offset s_0
        # behind the boresight.  With d from x0 alone, every run would start with the same
        # error of r along s_0, and the first seconds' pull would leave the drift biased
        # (-0.007 deg per step at 8 s on a noiseless link, doc/design/two_axis.md)
        self.x[:, 1:3] -= self.scan_offset
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        # what the filter sees from its first sample to its smooth_after-th, then over each
        # smooth_every samples (`window_smoother`): begun at a window's first update, from
        # the prior as it is then (whatever set it)
        self.window: Optional[WindowRecord] = None
        self.window_length = config.smooth_after
        self.to_smooth = config.smooth_after > 0
        self.smoothing_failures = 0                  # windows whose smoothing was not solvable
        self.clock = StampClock(config.dt)
        self.mu = 1.0                                # the last graininess seen
        self.regulator = TimeScaleLQR(0.0, 1.0, config.state_weight, config.input_weight)
        self.u = np.zeros((n, 2))                    # u_{k-1}, not yet predicted over
        self.y = np.zeros(n)                         # innovation of the last update
        self.S = np.full(n, np.nan)                  # its variance
        self.updated: NDArray[np.bool_] = np.zeros(n, dtype=bool)
        # the mount's tilt (deg), kept from the turns sent (a supervisor sets it from its joints)
        self.tilt = np.full(n, float(tilt0))

    @property
    def scan_offset(self) -> FloatArray:
        """s_k, the offset (2,) at which the next sample is taken; (runs, 2) with dim_radius."""
        if self.config.dim_radius > 0.0:
            return self.radius[:, None] * self.unit_scan[self.index]
        return self.scan[self.index]

    def propagate(self, x: FloatArray, P: FloatArray, mu: float, Bu: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return (F x + B u, F P F^T + mu Q, F) over mu nominal steps for each run."""
        F = transition(mu)
        x, P = kalman.predict_batch(x, np.ascontiguousarray(P), F, mu * self.Q, Bu)
        return x, P, F

    def predict(self, mu: float) -> None:
        """Predict over mu nominal steps: x <- F x + B u_{k-1}, P <- F P F^T + mu Q."""
        Bu = np.zeros((self.runs, 5))
        Bu[:, 1:3] = self.u
        self.x, self.P, F = self.propagate(self.x, self.P, mu, Bu)
        if self.window is not None:
            self.window.predicted(mu, Bu, F)
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

    def hessian(self, x: FloatArray, offset: FloatArray) -> FloatArray:
        """
        Return h_xx = d^2 h/dx^2 (runs, 5, 5).

        x1 times the Hessian of g_r(|d + s|) in d; its gradient in the (x1, d) cross
        terms; 0 for the drift.
        """
        e = x[:, 1:3] + offset
        Hxx = np.zeros((x.shape[0], 5, 5))
        Hxx[:, 0, 1:3] = Hxx[:, 1:3, 0] = self.response.gradient(e)
        Hxx[:, 1:3, 1:3] = x[:, 0, None, None] * self.response.hessian(e)
        return Hxx

    def linearise(self, x: FloatArray, P: FloatArray, offset: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """
        Return (H, hx, R_h): h(x') ~ H x' + (hx - H x), with R_h the variance that misses.

        'taylor', order 1: the EKF's Jacobian at x, R_h = 0.  Order 2, the Gaussian
        second-order filter (Athans, Wishner & Bertolini, IEEE TAC 1968; Gelb, Applied
        Optimal Estimation, 1974, Sec. 6.1; Bar-Shalom, Li & Kirubarajan 2001, Sec. 10.3):
        hx = h(x) + tr(h_xx P)/2 and R_h = tr(h_xx P h_xx P)/2, the mean and variance of
        the quadratic term of h under N(x, P).  'cubature' / 'gauss_hermite(_5)': the
        statistical linear regression of h over N(x, P) on the rule's points
        (`sigma_points.regression`); the linear update with them is the cubature
        (unscented) Kalman filter's, or the Gauss-Hermite filter's.  With 'taylor' and
        wide > 0, the runs whose pointing prior is wider than `wide` (the larger of the
        sd of d_c and d_e) take `wide_linearisation`'s regression instead (a prior with
        a pinned state, or not positive definite, keeps the Jacobian).
        """
        c = self.config
        if c.linearisation != 'taylor':
            return regression(c.linearisation, self.response.g, x, P, offset)
        H, hx, R_h = self.taylor(x, P, offset)
        if c.wide > 0.0:
            wide = np.maximum(P[:, 1, 1], P[:, 2, 2]) > c.wide * c.wide
            if np.any(wide):
                # only a positive definite [x1, d] block has the rule's Cholesky factor: a
                # pinned state (variance 0, as the one-axis reduction's) keeps the Jacobian
                block = P[wide, :3, :3]
                floor = 1e-12 * np.trace(block, axis1=1, axis2=2)
                wide[wide] = np.linalg.eigvalsh(block)[:, 0] > floor
            if np.any(wide):
                s = offset[wide] if np.ndim(offset) == 2 else offset
                H[wide], hx[wide], R_h[wide] = regression(c.wide_linearisation,
                                                          self.response.g, x[wide],
                                                          P[wide], s)
        return H, hx, R_h

    def taylor(self, x: FloatArray, P: FloatArray, offset: FloatArray
               ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return linearise's (H, hx, R_h) by the Taylor series (order 1 or 2) at x."""
        n = x.shape[0]
        H = self.jacobian(x, offset)
        hx = self.h(x, offset)
        if self.config.order == 1:
            return H, hx, np.zeros(n)
        HxxP = self.hessian(x, offset) @ P
        return (H, hx + 0.5 * np.einsum('rii->r', HxxP),
                0.5 * np.einsum('rij,rji->r', HxxP, HxxP))

    def update(self, z: FloatArray) -> None:
        """
        Update the runs whose z is finite: core.kalman's linear update, h linearised.

        The first pass linearises at the prior (`linearise`); with iterations > 1 each
        further pass linearises at the last posterior (x, P) and updates the prior again:
        Gauss-Newton on the update for 'taylor' order 1 (the iterated EKF, Bell & Cathey,
        IEEE TAC 1993), the iterated posterior linearisation filter for the sigma-point rules
        (Garcia-Fernandez, Svensson, Morelande & Sarkka, IEEE TSP 2015).  y and S (the
        NIS) are the first pass's, the innovation of the prior.  With innovation_clip c > 0,
        a sample whose first innovation y is beyond c sqrt(S) is taken as the predicted
        sample plus c sqrt(S) sign(y), for every pass: the saturated innovation of the
        robust filters (Masreliez & Martin, IEEE TAC 1977), bounding what one sample does.
        At the config's smooth_after-th sample, the runs not restarted since the start then
        take the estimate of the iterated smoother over the samples so far
        (`window_smoother.smooth_window`), and again at the end of each window of
        smooth_every samples after it, over that window, the runs not restarted within it
        (only their part of the record is smoothed); y and S stay the update's.  A
        smoothing that is not solvable (a linear algebra error) leaves every run the
        filter's estimate, counted in smoothing_failures; a run whose smoothed estimate is
        not finite keeps the filter's (not counted).
        """
        offset = self.scan_offset
        if self.to_smooth and self.window is None:
            self.window = WindowRecord(self.x, self.P)
        post = self.posterior(self.x, self.P, z, offset)
        if self.window is not None:
            self.window.updated(z, offset, (self.x, self.P), (post.x, post.P))
        self.x, self.P, self.y, self.S = post
        self.updated = np.isfinite(z)
        window = self.window
        if window is not None and window.count >= self.window_length:
            # the next window begins at the next sample, from the estimate there
            self.window, self.window_length = None, self.config.smooth_every
            self.to_smooth = self.window_length > 0
            keep = ~window.restarted
            if keep.any():
                try:
                    # only the runs kept: their recorded pass is the smoother's first
                    x, P = smooth_window(self, window if keep.all() else window.only(keep))
                except np.linalg.LinAlgError:
                    # the filter's estimate stands; the next window is smoothed as usual
                    self.smoothing_failures += 1
                else:
                    ok = np.isfinite(x).all(axis=1) & np.isfinite(P).all(axis=(1, 2))
                    runs = np.flatnonzero(keep)[ok]
                    self.x[runs], self.P[runs] = x[ok], P[ok]

    def posterior(self, x_prior: FloatArray, P_prior: FloatArray, z: FloatArray,
                  offset: FloatArray, nominal: Optional[tuple[FloatArray, FloatArray]] = None
                  ) -> Posterior:
        """
        Return `update`'s posterior of the prior (x_prior, P_prior) with z at offset.

        nominal (x, P): h linearised there, once, instead of at the prior (and at the
        passes' posteriors): the smoother's passes (`window_smoother`).
        """
        have = np.isfinite(z)
        zz = np.where(have, z, 0.0)[:, None]
        P_prior = np.ascontiguousarray(P_prior)
        x_lin, P_lin = (x_prior, P_prior) if nominal is None else nominal
        clip = self.config.innovation_clip
        passes = self.config.iterations if nominal is None else 1
        for i in range(passes):
            H, hx, R_h = self.linearise(x_lin, P_lin, offset)
            # H x + d = the predicted sample at the linearisation point: d = hx - H x_lin
            d = (hx - (H @ x_lin[:, :, None])[:, 0, 0])[:, None]
            R = self.R + R_h[:, None, None]
            x_lin, P_lin, y, S, _ = kalman.update_runs(x_prior, P_prior, zz, H, R, d)
            if i == 0 and clip > 0.0:
                limit = clip * np.sqrt(S[:, :, 0])
                if np.any(np.abs(y) > limit):
                    # z - y is the predicted sample: move z to within c sqrt(S) of it
                    zz = zz - y + np.clip(y, -limit, limit)
                    x_lin, P_lin, y, S, _ = kalman.update_runs(x_prior, P_prior, zz, H, R, d)
            if i == 0:
                y0, S0 = np.where(have, y[:, 0], 0.0), S[:, 0, 0]
        x = np.where(have[:, None], x_lin, x_prior)
        P = np.where(have[:, None, None], P_lin, P_prior)
        x[:, 0] = np.maximum(x[:, 0], self.config.x1_floor)
        return Posterior(x, P, y0, S0)

    def control(self) -> FloatArray:
        """Return the turn of the mean pointing per axis, (runs, 2), by the configured law."""
        c = self.config
        d, b = self.x[:, 1:3], self.x[:, 3:5]
        if c.controller == 'lqr':
            L = float(self.regulator.stationary(self.mu).L[0, 0])
            return lqr_turn(L, self.mu, d, b)
        # (21) per axis, u_k = -G dhat_k, less the drift of a step (not in the paper)
        return -c.gain * d - (b if c.feedforward else 0.0)

    def step(self, stamp: float, z: Measurement) -> FloatArray:
        """One sample at `stamp`: predict, update, control; return the turn (runs, 2)."""
        z = as_measurement(z, self.runs)
        mu = self.clock.tick(stamp)
        if mu is not None:
            self.predict(mu)
            self.mu = mu
        self.update(z)
        u = self.control()
        self.u = u
        s_now = self.scan_offset
        self.index = (self.index + 1) % len(self.scan)
        if self.config.dim_radius > 0.0:
            self.radius = dim_scan_radius(self.x[:, 0] * self.response.peak,
                                          self.config.radius, self.config.dim_radius,
                                          self.config.dim_peak)
        s_next = self.scan_offset
        turn = closed_scan_turn(u, s_now, s_next, self.tilt) if self.config.closed_scan \
            else u + s_next - s_now
        self.tilt = self.tilt + turn[:, 1]
        return turn

    @property
    def nis(self) -> FloatArray:
        """Return the NIS y^2 / S of the last update per run (NaN where z was missing)."""
        return np.where(self.updated, self.y * self.y / self.S, np.nan)

    def correct_last_turn(self, delta: FloatArray) -> None:
        """Account for a mount that turned delta (runs, 2) more than commanded (clamped)."""
        self.u = self.u + np.asarray(delta, dtype=float)
        self.tilt = self.tilt + np.asarray(delta, dtype=float)[:, 1]

    def restart_runs(self, mask: NDArray[np.bool_], x: FloatArray, P: FloatArray) -> None:
        """Start the runs in mask afresh from x (m, 5) and P (m, 5, 5); their next turn is 0."""
        if self.window is not None:
            self.window.restarted |= mask
        self.x[mask] = x
        self.P[mask] = P
        self.u[mask] = 0.0
