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
The alignment session's settings, checked when made: Table I of Solanki, Al-Rubaia & Tan 2018.

Section IV's observability condition (eq. (24), corrected: 0 < G < 2 and a scan without a
zero step; G <= 1/91 would guarantee det C_k != 0) is one of the checks; angles are in
degrees, intensities in volts.
"""

from dataclasses import dataclass, field
import math
from typing import Sequence

import numpy as np

from tskf_ros import led
from tskf_ros.led.intensity_model import FloatArray
from tskf_ros.led.pat_config import PatConfig
from tskf_ros.led.supervisor import SupervisorConfig

# parameters that change in place; any other change restarts the aligner
TUNABLE = ('gain', 'Q', 'R', 'x1_floor', 'gamma', 'clip', 'negative_is_missing', 'max_gap',
           'max_backward', 'gate', 'intensity_range', 'state_limit', 'max_step',
           'base_limits', 'expected_rate', 'rate_tolerance')


def _matrix(values: Sequence[float], name: str, *, definite: bool) -> FloatArray:
    """Return a flat 4-entry list as a symmetric 2 x 2 matrix; raise AlignmentError if bad."""
    v = np.asarray(list(values), dtype=float)
    if v.size != 4:
        raise led.AlignmentError(f'{name} must have 4 entries (2 x 2 row-major), got {v.size}')
    if not np.all(np.isfinite(v)):
        raise led.AlignmentError(f'{name} has non-finite entries')
    m = v.reshape(2, 2)
    if not np.allclose(m, m.T, rtol=0, atol=1e-12 * max(1.0, float(np.max(np.abs(m))))):
        raise led.AlignmentError(f'{name} must be symmetric, got {m.tolist()}')
    eig = np.linalg.eigvalsh(m)
    if (definite and not eig[0] > 0) or eig[0] < 0:
        kind = 'positive definite' if definite else 'positive semi-definite'
        raise led.AlignmentError(f'{name} must be {kind}; eigenvalues {eig.tolist()}')
    return m


def check_range(name: str, values: Sequence[float], *, empty: bool = False) -> None:
    """Raise AlignmentError unless values is [lo, hi] with finite lo < hi (or, if empty, [])."""
    r = tuple(values)
    if (r or not empty) and (len(r) != 2 or not all(math.isfinite(v) for v in r)
                             or not r[0] < r[1]):
        raise led.AlignmentError(f'{name} must be [lo, hi] with finite lo < hi'
                                 f'{" (or empty)" if empty else ""}, got {list(r)}')


@dataclass(frozen=True)
class AlignmentConfig:
    """The session's settings (Table I defaults); angles in degrees, intensities in volts."""

    algorithm: str = 'ekf'                       # one of led.ALGORITHMS
    controller: str = 'p'                        # ekf's controller: one of led.CONTROLLERS
    dt: float = led.PAPER_DT                     # s: the nominal sample period (mu = dt / dt)
    gain: float = led.PAPER_GAIN                 # G of the P controller (21)
    x0: tuple[float, ...] = led.PAPER_X0         # xhat_0 = [x1 (V), x2 (deg)]
    P0: tuple[float, ...] = tuple(np.ravel(led.PAPER_P0))    # 2 x 2 row-major
    Q: tuple[float, ...] = tuple(np.ravel(led.PAPER_Q))
    R: tuple[float, ...] = tuple(np.ravel(led.PAPER_R))
    scan: tuple[float, ...] = led.SCAN_ANGLES    # Psi (deg), visited cyclically
    x1_floor: float = 0.0                        # keep x1hat >= this; 0: off (the paper)
    gamma: float = led.HILL_STEP                 # deg: step of the two baselines
    clip: bool = False                           # three-point: guard eq. (26)
    units_per_degree: float = 0.0                # fit units of g per degree; 0: zone unit
    base_initial: float = 0.0                    # deg: base angle when the session starts
    negative_is_missing: bool = True             # a negative intensity is a missing sample
    max_gap: float = 1.0                         # s: a longer gap sets diagnostics to WARN
    max_backward: float = 5.0                    # s: a stamp further back restarts
    gate: float = 10.0                           # innovation gate (std devs); 0: off
    intensity_range: tuple[float, ...] = ()      # (lo, hi) V of a physical reading; (): any
    state_limit: float = 1e6                     # |x_i| or sqrt(trace P) beyond: restart
    max_step: float = 45.0                       # deg a command may turn the base; 0: any
    base_limits: tuple[float, ...] = (-360.0, 360.0)     # deg: the joint limits of the base
    expected_rate: float = 0.0                   # Hz of the input (FrequencyStatus); 0: 1/dt
    rate_tolerance: float = 0.5                  # FrequencyStatus's tolerance around it
    pat: PatConfig = field(default_factory=PatConfig)    # the pointing supervisor (pat.*)

    def __post_init__(self) -> None:
        """Check that the settings make a working aligner; raise AlignmentError if not."""
        if self.algorithm not in led.ALGORITHMS:
            raise led.AlignmentError(f'algorithm must be one of {led.ALGORITHMS}, '
                                     f'got {self.algorithm!r}')
        if self.controller not in led.CONTROLLERS:
            raise led.AlignmentError(f'controller must be one of {led.CONTROLLERS}, '
                                     f'got {self.controller!r}')
        for name in ('dt', 'gain', 'x1_floor', 'gamma', 'units_per_degree', 'base_initial',
                     'max_gap', 'max_backward', 'gate', 'state_limit', 'max_step',
                     'expected_rate', 'rate_tolerance'):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise led.AlignmentError(f'{name} must be finite, got {value}')
        for name in ('dt', 'gamma'):
            if not getattr(self, name) > 0:
                raise led.AlignmentError(f'{name} must be > 0, got {getattr(self, name)}')
        for name in ('x1_floor', 'units_per_degree', 'max_gap', 'max_backward', 'gate',
                     'max_step', 'expected_rate', 'rate_tolerance'):
            if getattr(self, name) < 0:
                raise led.AlignmentError(f'{name} must be >= 0, got {getattr(self, name)}')
        if not self.state_limit > 0:
            raise led.AlignmentError('state_limit must be > 0')
        check_range('intensity_range', self.intensity_range, empty=True)
        if tuple(self.base_limits):
            check_range('base_limits', self.base_limits)
        if len(tuple(self.base_limits)) != 2:
            raise led.AlignmentError(f'base_limits must be [lo, hi], got {list(self.base_limits)}')
        lo, hi = self.base_limits
        if not lo <= self.base_initial <= hi:
            raise led.AlignmentError(f'base_initial {self.base_initial} deg is outside '
                                     f'base_limits {list(self.base_limits)}')
        x0 = np.asarray(list(self.x0), dtype=float)
        if x0.size != 2 or not np.all(np.isfinite(x0)):
            raise led.AlignmentError(f'x0 must be 2 finite numbers [x1, x2], got {list(x0)}')
        if float(np.max(np.abs(x0))) > self.state_limit:
            raise led.AlignmentError(f'x0 {list(x0)} is beyond state_limit {self.state_limit:g}')
        P0 = _matrix(self.P0, 'P0', definite=False)
        Q = _matrix(self.Q, 'Q', definite=False)
        # by what they do: one nominal step from P0 must stay within state_limit
        if not float(np.trace(P0 + Q)) <= self.state_limit ** 2:
            raise led.AlignmentError(f'P0 + Q (one step) has sqrt(trace) '
                                     f'{math.sqrt(float(np.trace(P0 + Q))):.3g} beyond '
                                     f'state_limit {self.state_limit:g}')
        _matrix(self.R, 'R', definite=True)
        scan = np.asarray(list(self.scan), dtype=float)
        if not np.all(np.isfinite(scan)):
            raise led.AlignmentError('scan has non-finite angles')
        # Section IV, eq. (24) corrected: 0 < G < 2 and no zero scan step (where det C_k
        # can still vanish, as at the paper's G = 0.5: led.observability(...).message)
        led.observability(self.gain, tuple(scan))
        if self.pat.enabled:
            if self.controller != 'p':
                raise led.AlignmentError(f'pat.enabled needs controller p: the supervisor '
                                         f'cannot steer the {self.controller} controller')
            self.supervisor()

    def ekf(self) -> led.EKFConfig:
        """Return the scanning EKF's configuration."""
        return led.EKFConfig(
            x0=tuple(float(v) for v in self.x0),
            P0=tuple(map(tuple, _matrix(self.P0, 'P0', definite=False))),
            Q=tuple(map(tuple, _matrix(self.Q, 'Q', definite=False))),
            R=tuple(map(tuple, _matrix(self.R, 'R', definite=True))),
            gain=float(self.gain), scan=tuple(float(v) for v in self.scan), dt=float(self.dt),
            x1_floor=float(self.x1_floor) if self.x1_floor > 0 else None)

    def supervisor(self) -> SupervisorConfig:
        """Return the supervisor's config: pat.*, noise sqrt(R_11), max_step and gate."""
        return self.pat.supervisor(noise=math.sqrt(float(self.R[0])), max_step=self.max_step,
                                   gate=self.gate)

    def response(self) -> led.IncidenceResponse:
        """Return g of eq. (4) in the configured unit (0: the tracking-zone unit)."""
        return led.IncidenceResponse(units_per_degree=self.units_per_degree or None)

    def make_aligner(self) -> led.AnyAligner:
        """Build the configured aligner for one run."""
        return led.make_aligner(self.algorithm, runs=1, dt=self.dt, response=self.response(),
                                ekf=self.ekf(), gamma=self.gamma, clip=self.clip,
                                controller=self.controller, lqg=led.LQGConfig(dt=self.dt))
