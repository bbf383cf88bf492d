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

"""The NIS check against the chi-square band of the mean, written out from its definition."""

import numpy as np
import pytest
import scipy.stats

from tskf_ros.core.nis_check import nis_summary, nis_summary_of


def test_nis_band_is_the_chi_square_band_of_the_mean():
    rng = np.random.default_rng(3)
    s = nis_summary(rng.chisquare(2, 4000), 2)
    # the mean of N chi2(p) is chi2(N p) / N: mean p, variance 2 p / N
    half = 1.959964 * np.sqrt(2 * 2 / 4000)
    assert s['band'][0] == pytest.approx(2 - half, abs=2e-3)
    assert s['band'][1] == pytest.approx(2 + half, abs=2e-3)
    assert s['consistent'] and s['fraction_in_band'] == pytest.approx(0.95, abs=0.01)


def test_no_innovations_judge_nothing():
    s = nis_summary([], 1)
    assert s['n'] == 0 and s['consistent'] is None and s['mean'] is None


@pytest.mark.parametrize('p', [1, 2, 4])
def test_the_summary_from_sums_is_the_definition(p):
    # mean = np.mean, fraction = the share inside the single chi2(p) band, written out here
    rng = np.random.default_rng(p)
    nis = rng.chisquare(p, 10_001) * 1.03
    alpha = 1.0 - 0.95
    lo, hi = scipy.stats.chi2.ppf([alpha / 2, 1 - alpha / 2], p)
    inside = int(np.count_nonzero((nis >= lo) & (nis <= hi)))
    s = nis_summary_of(nis.size, np.sum(nis), inside, p)
    assert s == nis_summary(nis, p)
    assert s['mean'] == float(np.mean(nis)) and s['fraction_in_band'] == float(
        np.mean((nis >= lo) & (nis <= hi)))
    assert s['single_band'] == [float(lo), float(hi)]
