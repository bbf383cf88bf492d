"""
LED active alignment of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018).

intensity_model (eq. 1-5), scanning_ekf (eq. 7-24), baselines (Section V, eq. 26),
lqg_alignment (an LQG controller, not in the paper) and tracking_simulation (eq. 25,
Table I) are re-exported here, as filterpy.kalman does; led_link (the live plant),
alignment_config and alignment_session (behind the alignment node) are imported from
their modules.
"""

from tskf_ros.led.baselines import (ALGORITHMS, AnyAligner, CONTROLLERS, HILL_STEP, HillClimbing,
                                    make_aligner, ThreePointAveraging)
from tskf_ros.led.intensity_model import (AlignmentError, attenuation, IncidenceResponse,
                                          irradiance, LITERAL_UNITS_PER_DEGREE, MAX_INTENSITY,
                                          PAPER_G_COEFFICIENTS, TRACKING_ANGLE, TRACKING_LEVEL,
                                          wrap_degrees, zone_units_per_degree)
from tskf_ros.led.lqg_alignment import LQGAligner, LQGConfig, triangle_scan
from tskf_ros.led.scanning_ekf import (Aligner, as_measurement, check_observability, EKFConfig,
                                       max_gain, Measurement, Observability, observability,
                                       ObservabilityError, ObservabilityWarning, PAPER_DT,
                                       PAPER_GAIN, PAPER_P0, PAPER_Q, PAPER_Q_SYS, PAPER_R,
                                       PAPER_R_SYS, PAPER_X0, SCAN_ANGLES, ScanningEKF, StampClock)
from tskf_ros.led.tracking_simulation import (simulate_tracking, tracking, TrackingLinkConfig,
                                              Trajectory)

__all__ = [
    'ALGORITHMS', 'Aligner', 'AlignmentError', 'AnyAligner', 'as_measurement', 'attenuation',
    'check_observability', 'CONTROLLERS', 'EKFConfig', 'HILL_STEP', 'HillClimbing',
    'IncidenceResponse', 'irradiance', 'LITERAL_UNITS_PER_DEGREE', 'LQGAligner', 'LQGConfig',
    'make_aligner', 'MAX_INTENSITY', 'max_gain', 'Measurement', 'Observability',
    'observability', 'ObservabilityError', 'ObservabilityWarning',
    'PAPER_DT', 'PAPER_G_COEFFICIENTS', 'PAPER_GAIN', 'PAPER_P0', 'PAPER_Q', 'PAPER_Q_SYS',
    'PAPER_R', 'PAPER_R_SYS', 'PAPER_X0', 'SCAN_ANGLES', 'ScanningEKF', 'simulate_tracking',
    'StampClock', 'ThreePointAveraging', 'tracking', 'TRACKING_ANGLE', 'TRACKING_LEVEL',
    'TrackingLinkConfig', 'Trajectory', 'triangle_scan', 'wrap_degrees', 'zone_units_per_degree',
]
