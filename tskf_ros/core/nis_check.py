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
The NIS consistency check of a filter's innovations against the chi-square distribution.

NIS_k = e_k^T S_k^-1 e_k is chi2(p) for a consistent filter (Bar-Shalom, Li & Kirubarajan,
Estimation with Applications to Tracking and Navigation, Wiley 2001, Sec. 5.4); the mean of
N of them is chi2(N p) / N.
"""

from typing import NotRequired, Optional, TypedDict

import numpy as np
from numpy.typing import ArrayLike
import scipy.stats


class NisSummary(TypedDict):
    """The NIS check of `nis_summary` (None entries: no innovations to judge)."""

    n: int
    mean: Optional[float]
    expected: NotRequired[float]
    band: list[Optional[float]]
    consistent: Optional[bool]
    fraction_in_band: Optional[float]
    single_band: NotRequired[list[float]]
    level: float


def single_band(p: int, level: float = 0.95) -> tuple[float, float]:
    """Return the two-sided `level` band of one chi2(p) variable."""
    alpha = 1.0 - level
    lo, hi = scipy.stats.chi2.ppf([alpha / 2, 1 - alpha / 2], p)
    return float(lo), float(hi)


def nis_summary(nis: ArrayLike, p: int, level: float = 0.95) -> NisSummary:
    """
    Return the NIS consistency check of N innovations of dimension p.

    mean NIS against the two-sided `level` band of the mean of N chi2(p) variables,
    [chi2.ppf(a/2, N p) / N, chi2.ppf(1 - a/2, N p) / N], and the fraction of single NIS
    values inside the chi2(p) band of the same level (expected: `level`).
    """
    nis = np.asarray(nis, dtype=float)
    one_lo, one_hi = single_band(p, level)
    return nis_summary_of(int(nis.size), np.sum(nis),
                          int(np.count_nonzero((nis >= one_lo) & (nis <= one_hi))), p, level)


def nis_summary_of(n: int, total: float, inside: int, p: int,
                   level: float = 0.95) -> NisSummary:
    """
    Return nis_summary of N values from their sum and how many are inside the single band.

    What a stream's NIS are summed into, without keeping them (the same numbers as
    nis_summary given the values, for the same sum).
    """
    alpha = 1.0 - level
    if n == 0:
        return {'n': 0, 'mean': None, 'band': [None, None], 'consistent': None,
                'fraction_in_band': None, 'level': level}
    lo, hi = scipy.stats.chi2.ppf([alpha / 2, 1 - alpha / 2], n * p) / n
    one_lo, one_hi = single_band(p, level)
    mean = float(np.float64(total) / n)
    return {'n': n, 'mean': mean, 'expected': float(p), 'band': [float(lo), float(hi)],
            'consistent': bool(lo <= mean <= hi), 'fraction_in_band': inside / n,
            'single_band': [one_lo, one_hi], 'level': level}
