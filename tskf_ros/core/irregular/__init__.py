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
Kalman filtering with irregularly sampled measurements (Fang & de Callafon, CDC 2011).

switching: the switching filter (13)-(17) and the lifted filter (3)-(8); intervals:
pathological and degenerate intervals (Definitions 2-3); theorem1: Theorem 1 and
Corollaries 1-2; theorem2: the scalar peak-covariance bounds (22)-(25); jump_covariance:
the time-scale filter around one jump (not in the paper).
"""

from tskf_ros.core.irregular.after_jump import (jump_covariance, JumpCovariance,
                                                steady_covariance)
from tskf_ros.core.irregular.common import (CLUSTER_TOL, CRITERIA, interval, IrregularError,
                                            LOG_OVERFLOW, MODULUS_RTOL, NULL_TOL, RANK_TOL)
from tskf_ros.core.irregular.intervals import (degenerate_intervals, distinct_eigenvalues,
                                               eigenspace, Eigenvalue, IntervalChecker,
                                               is_detectable, is_unstable, pathological_intervals,
                                               resonate, same_modulus, sees_fully)
from tskf_ros.core.irregular.switching import (FilterHistory, lifted_matrices, run_lifted,
                                               run_switching, SwitchingKalmanFilter)
from tskf_ros.core.irregular.theorem1 import (corollary1, corollary2, interval_warnings, theorem1,
                                              Theorem1Check, UNDETECTABLE)
from tskf_ros.core.irregular.theorem2 import (scalar_fixed_point, scalar_peak_bounds,
                                              scalar_peak_map)

__all__ = ['CLUSTER_TOL', 'corollary1', 'corollary2', 'CRITERIA', 'degenerate_intervals',
           'distinct_eigenvalues', 'eigenspace', 'Eigenvalue', 'FilterHistory', 'interval',
           'interval_warnings', 'IntervalChecker', 'IrregularError', 'is_detectable',
           'is_unstable', 'jump_covariance', 'JumpCovariance', 'lifted_matrices', 'LOG_OVERFLOW',
           'MODULUS_RTOL', 'NULL_TOL', 'pathological_intervals', 'RANK_TOL', 'resonate',
           'run_lifted', 'run_switching', 'same_modulus', 'scalar_fixed_point',
           'scalar_peak_bounds', 'scalar_peak_map', 'sees_fully', 'steady_covariance',
           'SwitchingKalmanFilter', 'theorem1', 'Theorem1Check', 'UNDETECTABLE']
