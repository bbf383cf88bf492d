"""
The papers' mathematics: the time-scale Kalman filter, time scales, irregular sampling, models.

No I/O and no ROS: every module here imports only numpy, scipy and this folder.
"""

from tskf_ros.core.fixed_lag import FixedLagSmoother
from tskf_ros.core.lqg import TimeScaleLQG
from tskf_ros.core.lqr import LQRError, LQRGains, NotInvertibleError, TimeScaleLQR
from tskf_ros.core.smoother import rts_smooth, smooth_at, Smoothed
from tskf_ros.core.timescale_kalman import FilterError, TimeScaleKalmanFilter

__all__ = ['FilterError', 'FixedLagSmoother', 'LQRError', 'LQRGains', 'NotInvertibleError',
           'rts_smooth', 'smooth_at', 'Smoothed', 'TimeScaleKalmanFilter', 'TimeScaleLQG',
           'TimeScaleLQR']
