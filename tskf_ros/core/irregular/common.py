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

"""Errors and tolerances shared by the irregular-sampling modules (Fang & de Callafon 2011)."""

import math
from typing import SupportsInt

import numpy as np

# Default tolerances of the eigen-structure checks (all relative; see the functions).
CLUSTER_TOL = 1e-6      # eigenvalues closer than this * max(1, ||A||_2) are one eigenvalue
MODULUS_RTOL = 1e-8     # 'same modulus' and 'mu_i^k = mu_j^k' tolerance
NULL_TOL = 1e-7         # singular values of A - mu I below this * max(1, ||A||_2) span ker
RANK_TOL = 1e-8         # C U is rank deficient if sigma_min(C U) <= this * ||C||_2

CRITERIA = ('paper', 'detectability')
# log of the largest float: a power whose log is beyond this overflows
LOG_OVERFLOW = math.log(np.finfo(float).max)


class IrregularError(ValueError):
    """A model, interval set or sequence the irregular-sampling checks cannot use."""


def interval(kappa: SupportsInt) -> int:
    """Return kappa as a positive int, or raise."""
    try:
        k = int(kappa)
    except (TypeError, ValueError):
        raise IrregularError(f'a sampling interval must be an integer, got {kappa!r}') from None
    if k != kappa or k < 1:
        raise IrregularError(f'a sampling interval must be an integer >= 1, got {kappa!r}')
    return k
