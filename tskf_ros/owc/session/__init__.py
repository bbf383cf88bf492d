"""The estimator session of the OWC link: stamped samples in, time-scale filter estimates out."""

from tskf_ros.owc.session.config import ConfigError, EstimatorConfig, model_from_flat
from tskf_ros.owc.session.outcome import (Estimate, Jump, Outcome, REJECT_REASONS,
                                          RESET_REASONS, Stats)
from tskf_ros.owc.session.session import EstimatorSession

__all__ = ['ConfigError', 'Estimate', 'EstimatorConfig', 'EstimatorSession', 'Jump',
           'model_from_flat', 'Outcome', 'REJECT_REASONS', 'RESET_REASONS', 'Stats']
