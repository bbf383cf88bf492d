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
LED active alignment of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018).

intensity_model (eq. 1-5), scanning_ekf (eq. 7-24), baselines (Section V, eq. 26),
lqg_alignment (an LQG controller, not in the paper) and tracking_simulation (eq. 25,
Table I) are re-exported here, as filterpy.kalman does; led_link (the live plant),
alignment_config and alignment_session (behind the alignment node) are imported from
their modules.  The names are imported from their modules when first used.
"""

from typing import TYPE_CHECKING

from tskf_ros.core.lazy_names import lazy_names

if TYPE_CHECKING:
    from tskf_ros.led.baselines import (ALGORITHMS, AnyAligner, CONTROLLERS, HILL_STEP,
                                        HillClimbing, make_aligner, ThreePointAveraging)
    from tskf_ros.led.intensity_model import (AlignmentError, attenuation, IncidenceResponse,
                                              irradiance, LITERAL_UNITS_PER_DEGREE, MAX_INTENSITY,
                                              PAPER_G_COEFFICIENTS, TRACKING_ANGLE, TRACKING_LEVEL,
                                              wrap_degrees, zone_units_per_degree)
    from tskf_ros.led.lqg_alignment import (LQGAligner, LQGConfig, triangle_scan)
    from tskf_ros.led.scan_observability import (check_observability, max_gain,
                                                 Observability, observability,
                                                 ObservabilityError, ObservabilityWarning,
                                                 SCAN_ANGLES)
    from tskf_ros.led.scanning_ekf import (Aligner, as_measurement, EKFConfig, Measurement,
                                           PAPER_DT, PAPER_GAIN, PAPER_P0, PAPER_Q, PAPER_Q_SYS,
                                           PAPER_R, PAPER_R_SYS, PAPER_X0, ScanningEKF, StampClock)
    from tskf_ros.led.tracking_simulation import (Block, Disturbances, draw_disturbances,
                                                  simulate_blocks, simulate_tracking, tracking,
                                                  TrackingLinkConfig, Trajectory)

# each name and the module it comes from
_SOURCES = {
    'ALGORITHMS': 'baselines', 'AnyAligner': 'baselines', 'CONTROLLERS': 'baselines',
    'HILL_STEP': 'baselines', 'HillClimbing': 'baselines', 'make_aligner': 'baselines',
    'ThreePointAveraging': 'baselines', 'AlignmentError': 'intensity_model',
    'attenuation': 'intensity_model', 'IncidenceResponse': 'intensity_model',
    'irradiance': 'intensity_model', 'LITERAL_UNITS_PER_DEGREE': 'intensity_model',
    'MAX_INTENSITY': 'intensity_model', 'PAPER_G_COEFFICIENTS': 'intensity_model',
    'TRACKING_ANGLE': 'intensity_model', 'TRACKING_LEVEL': 'intensity_model',
    'wrap_degrees': 'intensity_model', 'zone_units_per_degree': 'intensity_model',
    'LQGAligner': 'lqg_alignment', 'LQGConfig': 'lqg_alignment',
    'triangle_scan': 'lqg_alignment', 'Aligner': 'scanning_ekf',
    'as_measurement': 'scanning_ekf', 'check_observability': 'scan_observability',
    'EKFConfig': 'scanning_ekf', 'Measurement': 'scanning_ekf',
    'max_gain': 'scan_observability', 'Observability': 'scan_observability',
    'observability': 'scan_observability',
    'ObservabilityWarning': 'scan_observability',
    'ObservabilityError': 'scan_observability', 'PAPER_DT': 'scanning_ekf',
    'PAPER_GAIN': 'scanning_ekf', 'PAPER_P0': 'scanning_ekf', 'PAPER_Q': 'scanning_ekf',
    'PAPER_Q_SYS': 'scanning_ekf', 'PAPER_R': 'scanning_ekf', 'PAPER_R_SYS': 'scanning_ekf',
    'PAPER_X0': 'scanning_ekf', 'SCAN_ANGLES': 'scan_observability',
    'ScanningEKF': 'scanning_ekf',
    'StampClock': 'scanning_ekf', 'simulate_tracking': 'tracking_simulation',
    'tracking': 'tracking_simulation', 'TrackingLinkConfig': 'tracking_simulation',
    'Trajectory': 'tracking_simulation', 'Block': 'tracking_simulation',
    'Disturbances': 'tracking_simulation', 'draw_disturbances': 'tracking_simulation',
    'simulate_blocks': 'tracking_simulation',
}

__all__ = [
    'ALGORITHMS', 'Aligner', 'AlignmentError', 'AnyAligner', 'as_measurement', 'attenuation',
    'Block', 'check_observability', 'CONTROLLERS', 'Disturbances', 'draw_disturbances',
    'EKFConfig', 'HILL_STEP', 'HillClimbing',
    'IncidenceResponse', 'irradiance', 'LITERAL_UNITS_PER_DEGREE', 'LQGAligner', 'LQGConfig',
    'make_aligner', 'MAX_INTENSITY', 'max_gain', 'Measurement', 'Observability',
    'observability', 'ObservabilityError', 'ObservabilityWarning',
    'PAPER_DT', 'PAPER_G_COEFFICIENTS', 'PAPER_GAIN', 'PAPER_P0', 'PAPER_Q', 'PAPER_Q_SYS',
    'PAPER_R', 'PAPER_R_SYS', 'PAPER_X0', 'SCAN_ANGLES', 'ScanningEKF', 'simulate_blocks',
    'simulate_tracking',
    'StampClock', 'ThreePointAveraging', 'tracking', 'TRACKING_ANGLE', 'TRACKING_LEVEL',
    'TrackingLinkConfig', 'Trajectory', 'triangle_scan', 'wrap_degrees', 'zone_units_per_degree',
]

__getattr__, __dir__ = lazy_names(__name__, _SOURCES, globals())
