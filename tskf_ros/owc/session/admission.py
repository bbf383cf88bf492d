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
What a sample must pass before it is a point: stamp, finite reading, range, innovation gate.

The gate (as robot_localization's per-sensor rejection threshold) is the Mahalanobis
distance of the innovation at the predictor (xhat, P) of the sample's own stamp:

    e = y - C xhat - D,   S = C P C^T + R_d,   d^2 = e^T S^-1 e > gate^2: rejected
    (kalman.mahalanobis2; no verdict when S is singular)

with R_d = R / period, or the sample's own variance (use_message_variance).
"""

import math
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import kalman
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.owc.session.config import EstimatorConfig
from tskf_ros.owc.session.outcome import FloatArray, Reading

_INF = math.inf


class Rejection(NamedTuple):
    """Why a sample is not a point: its counter, a one-line message, and the status."""

    reason: str
    message: str
    status: str = 'rejected'        # 'gap' for a reading that is an interruption


def _shown(y: Reading) -> str:
    """Return a reading as the messages show it, as an array: [v] or [v1 v2]."""
    return str(np.atleast_1d(y))


def stamp_rejection(stamp_ns: int, *, input_sample: bool = False) -> Optional[Rejection]:
    """Return why a header stamp cannot be a point (unset, or beyond int32 seconds)."""
    what = 'input ' if input_sample else ''
    if stamp_ns <= 0:
        return Rejection('input_zero_stamp' if input_sample else 'zero_stamp',
                         f'the {what}header stamp is unset (0)')
    if stamp_ns > MAX_STAMP_NS:
        return Rejection('stamp_range', f'{what}stamp {stamp_ns} ns is beyond what a ROS '
                         'message can hold (sec is an int32)')
    return None


class Admission:
    """The checks of a measurement sample before it reaches the filter, for one config."""

    def __init__(self, config: EstimatorConfig, p: int) -> None:
        self.p = p
        # a reading is a point when it is above low (Cai IV-C: <= 0 is an interruption)
        self.low = 0.0 if config.nonpositive_is_gap else -_INF
        self.range = tuple(config.measurement_range)
        self.lo, self.hi = self.range or (-_INF, _INF)
        self.max_future_ns = config.max_future * NS if config.max_future > 0 else _INF

    def check(self, stamp_ns: int, y: Reading, variance: float,
              now_ns: Optional[int]) -> Optional[Rejection]:
        """Return why the sample (stamp, reading y, its variance) is not a point, or None."""
        if not 0 < stamp_ns <= MAX_STAMP_NS:
            return stamp_rejection(stamp_ns)
        if isinstance(y, float):
            size, lowest, highest, finite = 1, y, y, math.isfinite(y)
        else:
            values = y.tolist()
            size, finite = len(values), all(map(math.isfinite, values))
            lowest, highest = min(values, default=0.0), max(values, default=0.0)
        if not finite:
            return Rejection('non_finite', f'measurement {_shown(y)} is not finite')
        if not 0.0 <= variance < _INF:
            return Rejection('bad_variance', f'variance {variance} is not a finite value >= 0')
        if size != self.p:
            return Rejection('bad_size', f'measurement has {size} entries, the model {self.p}')
        if not lowest > self.low:
            return Rejection('invalid_power', f'reading {_shown(y)} <= 0: an interruption',
                             'gap')
        if not (self.lo <= lowest and highest <= self.hi):
            return Rejection('out_of_range', f'reading {_shown(y)} outside measurement_range '
                             f'{list(self.range)}')
        if now_ns is not None and stamp_ns - now_ns > self.max_future_ns:
            return Rejection('future', f'stamp {stamp_ns / NS:.9f} s is '
                             f'{(stamp_ns - now_ns) / NS:.3f} s ahead of the clock')
        return None

    def passes(self, stamps_ns: NDArray[np.int64], ys: NDArray[np.float64],
               variances: NDArray[np.float64], nows_ns: NDArray[np.int64]
               ) -> NDArray[np.bool_]:
        """Tell, for samples of one reading each (p = 1), which check() lets through."""
        with np.errstate(invalid='ignore'):
            return ((0 < stamps_ns) & (stamps_ns <= MAX_STAMP_NS) & np.isfinite(ys)
                    & (0.0 <= variances) & (variances < _INF) & (self.p == 1)
                    & (ys > self.low) & (self.lo <= ys) & (ys <= self.hi)
                    & ~(stamps_ns - nows_ns > self.max_future_ns))


class Gate:
    """The innovation gate of one config and model (see the module docstring)."""

    def __init__(self, config: EstimatorConfig, kf: TimeScaleKalmanFilter) -> None:
        self.gate = config.gate
        self.on = config.gate > 0
        self.C, self.D = kf.C, kf.D
        self.R_period = kf.R / config.period
        self.p = kf.p
        self._innovation = np.empty(kf.p)      # written by each test (read in its message)

    def why(self, y: Reading, x: FloatArray, P: FloatArray, variance: float) -> str:
        """Return why y fails the gate at the predictor (x, P), or ''."""
        if not self.on:
            return ''
        z = np.array((y,)) if isinstance(y, float) else y
        Rd = np.eye(self.p) * variance if variance > 0 else self.R_period
        innovation = self._innovation
        d2 = kalman.mahalanobis2_into(x, P, z, self.C, Rd, self.D, innovation)
        gate = self.gate
        if d2 < 0.0 or d2 <= gate * gate:      # d2 < 0: S is singular, no distance
            return ''
        return (f'innovation {innovation} is {math.sqrt(abs(d2)):.3g} standard deviations '
                f'from the prediction (gate {gate:g})')
