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
The conical-scan EKF's parameters (`ConicalEKFConfig`) and the consistent filter's (`CONSISTENT`).

What each parameter does, and where its default was measured, is in the comments; the
filter itself is `conical_ekf.ConicalScanEKF`.
"""

from dataclasses import dataclass
import math

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.scanning_ekf import PAPER_DT

CONTROLLERS = ('p', 'lqr')
LINEARISATIONS = ('taylor', 'cubature', 'gauss_hermite', 'gauss_hermite_5')
# the bound of smooth_after and smooth_every: a window's record (the filter's own pass)
# keeps about 0.5 KiB a sample and run, and the smoother's passes peak at about 1 KiB more
# (0.6 MiB for one run over 400 samples, about 0.6 GiB for 1000 runs); 0.07 to 0.13 s for
# one run
MAX_SMOOTH_AFTER = 400
STATES = ('x1', 'd_c', 'd_e', 'b_c', 'b_e')


@dataclass(frozen=True)
class ConicalEKFConfig:
    """The conical-scan EKF's parameters; angles in degrees, intensities in volts."""

    radius: float = 4.0               # r of the scan circle (deg)
    points: int = 20                  # samples per scan turn (1 s at 50 ms, as Psi)
    # the radius when the light is dim (deg; 0: off, r stays `radius`): r widens linearly
    # from `radius` at x1hat g_r(0) = dim_peak to dim_radius at dim_peak / 2 and narrows
    # back to `radius` at dim_peak / 4 (scan_radius; 6.5 deg, where |g_r'| peaks: fewer
    # runs lost at 1 V and above, doc/design/two_axis.md)
    dim_radius: float = 6.5
    dim_peak: float = 2.0             # V
    # x0 = (x1, d_c, d_e, b_c, b_e), d being the boresight's error at the first sample
    # (the filter's d, the mean pointing's, starts at it less the scan's first offset)
    x0: tuple[float, ...] = (2.0, 0.0, 0.0, 0.0, 0.0)
    # P0: x1 as ekf_pat's clipped prior (2 V), d 5 deg, drift 0.063 deg per step (1.26
    # deg/s: the link's 1.2 deg/s per joint axis; a wider prior let the first seconds'
    # pull on d leak into a drift of the wrong sign, which the feedforward then steered)
    P0: tuple[float, ...] = (4.0, 25.0, 25.0, 0.004, 0.004)
    # Q per nominal step: Table I's Q_sys for x1; twice its 0.01 per pointing axis; the
    # drift's walk at the link's size (1e-8, as CONSISTENT: the link's drift walks by a
    # variance of about 2e-9 per step), so that bhat is the drift of the whole lock and
    # a fade hold steers on it (1e-5 let the dim samples before a fade carry bhat off:
    # 140 runs of 250 000 lost at the end at 1 V against 106).  The defaults are the
    # closed loop's (see CONSISTENT for the filter whose NEES is in its band, and
    # doc/design/two_axis.md for why the closed loop keeps these)
    Q: tuple[float, ...] = (0.0025, 0.02, 0.02, 1e-8, 1e-8)
    noise: float = 0.2                # sigma of v (V)
    # V: added to the noise in R = noise^2 + model_noise^2.  0.2 V is not what h misses
    # (0.0035 V, CONSISTENT): with the first-order update it keeps a noiseless link from
    # diverging, which it does at 0.0035 V (the second-order update does not need it)
    model_noise: float = 0.2
    # with 'taylor': 1, the EKF's first-order update; 2, the Gaussian second-order
    # filter's (the curvature of h in the predicted sample and in S; `linearise`)
    order: int = 1
    # how h is linearised: 'taylor' (order 1 or 2), or the regression over the sigma points
    # 'cubature', 'gauss_hermite' or 'gauss_hermite_5' (SIGMA_POINTS, `linearise`)
    linearisation: str = 'taylor'
    # deg (0: off, the default): with 'taylor', the runs whose pointing prior is wider than
    # this (the larger sd of d_c, d_e) are linearised by `wide_linearisation` instead, as
    # after a start or a hand-over, or in a long hold, where the Jacobian at dhat misses
    # what h does over a prior several degrees wide (`linearise`).  At 2.5 deg: 115 runs
    # of 450 000 lost at the end at 1 V against 141 (with the start of before), and the
    # ANEES in its band from 1 to 2.5 V, but more runs lost above 1 V (30 against 19 at
    # 1.5 V, 225 against 173 at 2 V; with the start behind the boresight, 7 against 8 over
    # 50 seeds at 1 V, 53 against 46 at 1.5 V and 345 against 304 at 2 V over seeds 0 to
    # 9; 52 against 50 over seeds 100 to 299 at 1 V), so off (doc/design/two_axis.md,
    # "Sigma points while the pointing prior is wide")
    wide: float = 0.0
    wide_linearisation: str = 'gauss_hermite_5'
    iterations: int = 1               # passes of the update (> 1: iterated, `update`)
    # samples (0: off): at the filter's smooth_after-th sample, the runs not started afresh
    # since its start take the estimate of the iterated smoother over those samples
    # (`window_smoother`: each sample relinearised where the smoother puts it, not at its
    # prior), which corrects the drift that the first seconds' linearisation left.  100
    # (5 s at 50 ms): 62 runs of 300 000 lost at the end at 1 V against 80 (seeds 100 to
    # 399), 561 against 633 at 2 V (doc/design/two_axis.md, "The first samples smoothed")
    smooth_after: int = 100
    # samples (0: once only): after that, the filter's samples are smoothed again every
    # smooth_every samples, each window from the filter's estimate where it begins, which
    # corrects what the lock's own linearisation puts into the drift.  50: 91 runs of
    # 650 000 lost at the end at 1 V against 120 smoothed once (37 / 8, p = 2e-5), 461
    # against 561 at 2 V (doc/design/two_axis.md, "Smoothed again while locked")
    smooth_every: int = 50
    # the innovation is clipped to this many of its standard deviations sqrt(S) (0: off):
    # one sample far off the light, a spike of 30 V on a 3 V link, then moves the estimate
    # as a 6-sigma sample does, instead of tens of degrees (`update`; the closed loop's
    # NIS stayed under 24 over seed 0's 400 000 updates at every level from 0 to 2.5 V)
    innovation_clip: float = 6.0
    gain: float = 0.5                 # G of the P law (21), per axis
    feedforward: bool = True          # subtract bhat from u (not in the paper)
    controller: str = 'p'             # 'p' (21), or 'lqr' (lqg_alignment's regulator)
    state_weight: float = 0.25        # the LQR's weights of d and of the turn rate
    input_weight: float = 2.0
    dt: float = PAPER_DT
    x1_floor: float = 0.05            # x1hat is kept >= this (Section IV assumes x1 > 0)
    # send each turn so that the scan's circle closes in joints at the mount's tilt
    # (pointing_geometry.closed_scan_turn); False: u + s_{k+1} - s_k, whose circle creeps
    # by pi r^2 tan e per turn, which bhat absorbs, worse at high elevation
    # (doc/design/two_axis.md, "The scan closed in joints")
    closed_scan: bool = True

    def __post_init__(self) -> None:
        """Check every parameter; raise AlignmentError with the reason."""
        if len(self.x0) != 5 or len(self.P0) != 5 or len(self.Q) != 5:
            raise AlignmentError(f'x0, P0 and Q need 5 entries ({", ".join(STATES)})')
        values = (self.radius, self.dim_radius, self.dim_peak, self.noise, self.gain,
                  self.dt, self.x1_floor, self.wide, self.innovation_clip,
                  *self.x0, *self.P0, *self.Q)
        if not all(math.isfinite(v) for v in values):
            raise AlignmentError('every conical-scan EKF parameter must be finite')
        if min(self.P0) < 0.0 or min(self.Q) < 0.0:
            raise AlignmentError('P0 and Q must be >= 0')
        if self.innovation_clip < 0.0:
            raise AlignmentError(f'innovation_clip must be >= 0 (0: off), got '
                                 f'{self.innovation_clip}')
        if self.noise < 0.0 or self.model_noise < 0.0 or not self.noise + self.model_noise > 0:
            raise AlignmentError(f'noise and model_noise must be >= 0 V, one > 0, got '
                                 f'{self.noise}, {self.model_noise}')
        if not 0.0 < self.gain < 2.0:
            raise AlignmentError(f'gain G must be in (0, 2) (u = -G dhat), got {self.gain}')
        if not self.dt > 0.0:
            raise AlignmentError(f'dt must be > 0 s, got {self.dt}')
        if self.controller not in CONTROLLERS:
            raise AlignmentError(f'controller must be one of {CONTROLLERS}, '
                                 f'got {self.controller!r}')
        if not (self.state_weight > 0.0 and self.input_weight > 0.0):
            raise AlignmentError('the LQR weights must be > 0')
        if not 0.0 < self.radius < 15.0:
            raise AlignmentError(f'radius must be in (0, 15) deg, got {self.radius}')
        if self.dim_radius < 0.0 or self.dim_radius >= 15.0 or not self.dim_peak > 0.0:
            raise AlignmentError(f'dim_radius must be in [0, 15) deg (0: off) and dim_peak '
                                 f'> 0 V, got {self.dim_radius}, {self.dim_peak}')
        if self.points < 3:
            raise AlignmentError(f'the scan needs at least 3 points, got {self.points}')
        if self.order not in (1, 2):
            raise AlignmentError(f'order must be 1 (EKF) or 2 (second-order), got {self.order}')
        if self.linearisation not in LINEARISATIONS:
            raise AlignmentError(f'linearisation must be one of {LINEARISATIONS}, '
                                 f'got {self.linearisation!r}')
        if self.wide_linearisation not in LINEARISATIONS[1:] or not self.wide >= 0.0:
            raise AlignmentError(f'wide_linearisation must be one of {LINEARISATIONS[1:]} '
                                 f'and wide >= 0 deg, got {self.wide_linearisation!r}, '
                                 f'{self.wide}')
        if not 1 <= self.iterations <= 20:
            raise AlignmentError(f'iterations must be in [1, 20], got {self.iterations}')
        if not 0 <= self.smooth_after <= MAX_SMOOTH_AFTER:
            raise AlignmentError(f'smooth_after must be in [0, {MAX_SMOOTH_AFTER}] samples '
                                 f'(0: off), got {self.smooth_after}')
        if not 0 <= self.smooth_every <= MAX_SMOOTH_AFTER:
            raise AlignmentError(f'smooth_every must be in [0, {MAX_SMOOTH_AFTER}] samples '
                                 f'(0: once only), got {self.smooth_every}')


# The consistent filter: h linearised by the Gauss-Hermite regression over the prior, one
# pass, and R and Q from what the plant does.  One pass, not two (the update relinearised
# at its first posterior): over 40 seeds not looked at before (30 to 69), the ANEES of two
# passes was 2 to 9 % over 3 and out of its band at some level on 11 seeds, the intensity
# overconfident where the light is dim; one pass's is within 4 % of 3 up to 2 V (2.86 at
# 2.5 V, conservative) and out on 1 seed (doc/design/two_axis.md, "Consistency").  The rule
# has 5 points per axis: over the priors of 2 to 2.5 V (the pointing 5 to 7 deg wide) the
# 3-point rule, its nodes at +-sqrt(3) sd, overstates Var h by 8 and 33 % and so S (at
# 2.5 V, seed 0: Var h 0.95 V^2 against 0.72 by an 11-point rule, the mean NIS 0.930; with
# 5 points 0.967; doc/design/two_axis.md, "Consistency").
# model_noise: h at the true state differs from the noiseless sample by 0.0033 V at 0 V
# and 0.0036 V at 1 V (standard deviation, closed loop, 200 runs): the small-angle
# |d + s| for the exact angle on the sphere.  Q: Table I's Q_sys, 0.0025 for x1 and 0.01
# per pointing axis (the link's walks, exactly); the drift b walks by about 2e-9 per step
# in the link (the source's drift changing with its elevation): 1e-8 here, the ANEES the
# same to 0.01 with 1e-7 (doc/design/two_axis.md).  No smoother (smooth_after 0): it was
# chosen and tested without one.  With the first 100 samples smoothed once, the covariance
# after them was conservative at 2.5 V (ANEES 2.60 on seed 0, under the band's 2.62); with
# the windows every 50 samples after it as well, 3.02, 2.95, 2.99, 3.03, 3.02 and 2.69 from
# 0 to 2.5 V on seed 0, all in the band.
CONSISTENT = ConicalEKFConfig(linearisation='gauss_hermite_5', iterations=1,
                              model_noise=0.0035, Q=(0.0025, 0.01, 0.01, 1e-8, 1e-8),
                              smooth_after=0)
