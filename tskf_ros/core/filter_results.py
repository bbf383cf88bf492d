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

"""What the time-scale Kalman filter's `step` and `run` give, and the test a run may apply."""

from dataclasses import dataclass
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['InnovationTest', 'RunResult', 'StepResult']


@dataclass(slots=True)
class StepResult:
    """What one step produced: the corrected estimate at t and the prediction at sigma(t)."""

    mu: float
    x_corrected: Vector
    P_corrected: Matrix
    x_predicted: Vector
    P_predicted: Matrix
    innovation: Vector
    S: Matrix


class InnovationTest(NamedTuple):
    """Keep step k of a run only if y^T S^-1 y <= limit2 for z[k] at its prediction, R."""

    z: Matrix           # K x p
    R: Matrix           # p x p
    limit2: float


class RunResult(NamedTuple):
    """What `run` kept: one row per step made, oldest first, and why it stopped ('' if not)."""

    steps: int
    x_corrected: Matrix     # steps x n
    P_corrected: NDArray[np.float64]    # steps x n x n
    x_predicted: Matrix
    P_predicted: NDArray[np.float64]
    stopped: str            # '' all made, 'refused' (step would raise), 'test' (failed it)
    innovation: Optional[Matrix] = None     # steps x p, with run(innovations=True)
    S: Optional[NDArray[np.float64]] = None     # steps x p x p, the same
