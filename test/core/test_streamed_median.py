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

"""The streamed median against np.median, bit for bit."""

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from tskf_ros.core.streamed_median import kth_smallest, median


def blocks_of(x: np.ndarray, size: int):
    return lambda: (x[i:i + size] for i in range(0, x.size, size))


@settings(max_examples=80, deadline=None)
@given(n=st.integers(1, 5000), kind=st.sampled_from(['wide', 'positive', 'ties', 'few']),
       size=st.integers(1, 3000), seed=st.integers(0, 2**32 - 1))
def test_the_median_is_numpys(n, kind, size, seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n) * np.exp(rng.uniform(-300, 300, n))
    if kind == 'positive':
        x = np.abs(x)
    elif kind == 'ties':
        x = np.round(rng.standard_normal(n) * 3)
        x[x == 0] = 0.0         # no -0.0: np.median does not tell it from 0.0
    elif kind == 'few':
        x = rng.integers(0, 3, n).astype(float)
    assert np.float64(median(blocks_of(x, size))).tobytes() == np.float64(np.median(x)).tobytes()


def test_kth_smallest_is_the_sorted_value():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.standard_normal(999), [np.inf, -np.inf, 0.0, 5e-324]])
    ordered = np.sort(x)
    for k in (0, 1, 500, 1001, 1002):
        assert kth_smallest(blocks_of(x, 64), k) == ordered[k]
    with pytest.raises(IndexError):
        kth_smallest(blocks_of(x, 64), x.size)


def test_nan_and_nothing_give_nan():
    assert np.isnan(median(blocks_of(np.array([1.0, np.nan, 2.0]), 2)))
    assert np.isnan(median(blocks_of(np.zeros(0), 2)))
