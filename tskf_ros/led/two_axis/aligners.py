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
The two-axis aligners by name, for the session, the node and the Monte Carlo experiment.

'conical_ekf': the conical-scan EKF with the per-axis P law (conical_ekf), from a known
prior; 'conical_ekf_pat': the same inside the acquiring / tracking / lost supervisor
(pan_tilt_supervisor); 'conical_lqg': the conical-scan EKF with the drift states and the
time-scale LQR per axis (conical_lqg).
"""

from dataclasses import replace
import math
from typing import Optional, Union

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.scanning_ekf import PAPER_DT
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig, ConicalScanEKF
from tskf_ros.led.two_axis.pan_tilt_supervisor import PanTiltSupervisor
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig
from tskf_ros.led.two_axis.radial_response import RadialResponse

METHODS = ('conical_ekf', 'conical_ekf_pat', 'conical_lqg')
STARTS = ('tracking', 'acquiring')

TwoAxisTracker = Union[ConicalScanEKF, PanTiltSupervisor]


def make_two_axis_aligner(method: str, *, runs: int = 1, noise: float = 0.2,
                          dt: float = PAPER_DT, start: str = 'tracking',
                          response: Optional[RadialResponse] = None,
                          ekf: Optional[ConicalEKFConfig] = None,
                          supervisor: Optional[PanTiltSupervisorConfig] = None,
                          joints0: tuple[float, float] = (0.0, 20.0)) -> TwoAxisTracker:
    """
    Build the two-axis aligner `method` (one of METHODS) for `runs` independent runs.

    noise: the sigma of v (V) the filter assumes (R = noise^2); dt: the nominal sample
    interval (s); start: 'tracking' (from the prior x0, P0) or 'acquiring' (a cold search,
    with the supervisor only); ekf: the conical-scan EKF's settings (its noise and dt are
    replaced by these); supervisor: the supervisor's (its start and noise replaced: the
    hand-over fit assumes the filter's sqrt(R)); joints0: the mount's [pan, tilt] at the
    start (deg), which the supervisor follows to search on the sphere.
    """
    if method not in METHODS:
        raise AlignmentError(f'unknown two-axis method {method!r}; one of {", ".join(METHODS)}')
    if start not in STARTS:
        raise AlignmentError(f'start must be one of {", ".join(STARTS)}, got {start!r}')
    config = replace(ekf if ekf is not None else ConicalEKFConfig(), noise=noise, dt=dt)
    if method == 'conical_ekf_pat':
        sup = replace(supervisor if supervisor is not None else PanTiltSupervisorConfig(),
                      start=start, noise=math.hypot(config.noise, config.model_noise))
        return PanTiltSupervisor(ConicalScanEKF(config, response, runs=runs, tilt0=joints0[1]),
                                 sup, response, joints0=joints0)
    if start != 'tracking':
        raise AlignmentError("only 'conical_ekf_pat' can start by acquiring")
    if method == 'conical_lqg':
        config = replace(config, controller='lqr')
    return ConicalScanEKF(config, response, runs=runs, tilt0=joints0[1])
