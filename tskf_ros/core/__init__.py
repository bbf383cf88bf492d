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
The papers' mathematics: the time-scale Kalman filter, time scales, irregular sampling, models.

No I/O and no ROS: every module here imports only numpy, scipy and this folder.  The names
below are imported from their modules when first used (a node imports only what it runs).
"""

from typing import TYPE_CHECKING

from tskf_ros.core.lazy_names import lazy_names

if TYPE_CHECKING:
    from tskf_ros.core.fixed_lag import FixedLagSmoother
    from tskf_ros.core.lqg import TimeScaleLQG
    from tskf_ros.core.lqr import LQRError, LQRGains, NotInvertibleError, TimeScaleLQR
    from tskf_ros.core.smoother import rts_smooth, smooth_at, Smoothed
    from tskf_ros.core.timescale_kalman import FilterError, TimeScaleKalmanFilter

# each name and the module it comes from
_SOURCES = {
    'FixedLagSmoother': 'fixed_lag', 'TimeScaleLQG': 'lqg', 'LQRError': 'lqr',
    'LQRGains': 'lqr', 'NotInvertibleError': 'lqr', 'TimeScaleLQR': 'lqr',
    'rts_smooth': 'smoother', 'smooth_at': 'smoother', 'Smoothed': 'smoother',
    'FilterError': 'timescale_kalman', 'TimeScaleKalmanFilter': 'timescale_kalman',
}

__all__ = ['FilterError', 'FixedLagSmoother', 'LQRError', 'LQRGains', 'NotInvertibleError',
           'rts_smooth', 'smooth_at', 'Smoothed', 'TimeScaleKalmanFilter', 'TimeScaleLQG',
           'TimeScaleLQR']

__getattr__, __dir__ = lazy_names(__name__, _SOURCES, globals())
