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

"""The estimator session of the OWC link: stamped samples in, time-scale filter estimates out."""

from tskf_ros.owc.session.config import ConfigError, EstimatorConfig, model_from_flat
from tskf_ros.owc.session.outcome import (Estimate, Jump, Outcome, REJECT_REASONS,
                                          RESET_REASONS, Stats)
from tskf_ros.owc.session.session import EstimatorSession

__all__ = ['ConfigError', 'Estimate', 'EstimatorConfig', 'EstimatorSession', 'Jump',
           'model_from_flat', 'Outcome', 'REJECT_REASONS', 'RESET_REASONS', 'Stats']
