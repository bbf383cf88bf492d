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

"""PairwiseSum against np.sum of the whole array, bit for bit, whatever the blocks."""

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from tskf_ros.core.pairwise_sum import leaf_sizes, pairwise_sum, PairwiseSum


def bits(x: float) -> bytes:
    return np.float64(x).tobytes()


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 300_000), leaf=st.sampled_from([128, 1024, 65536]),
       cut=st.integers(1, 50_000), seed=st.integers(0, 2**32 - 1))
def test_the_sum_is_numpys_bit_for_bit(n, leaf, cut, seed):
    rng = np.random.default_rng(seed)
    # magnitudes over 2^-40 .. 2^40: the order of the additions shows in the last bits
    x = rng.standard_normal(n) * np.exp2(rng.uniform(-40, 40, n))
    acc = PairwiseSum(n, leaf)
    for start in range(0, n, cut):
        acc.add(x[start:start + cut])
    assert bits(acc.total()) == bits(np.sum(x))
    assert sum(leaf_sizes(n, leaf)) == n


def test_a_long_column_in_blocks_of_a_file_size():
    rng = np.random.default_rng(7)
    x = rng.standard_normal(2_000_003) * np.exp2(rng.uniform(-30, 30, 2_000_003))
    blocks = (x[i:i + 16384] for i in range(0, x.size, 16384))
    assert bits(pairwise_sum(blocks, x.size)) == bits(np.sum(x))


def test_misuse_is_refused():
    with pytest.raises(ValueError, match='multiple of 8'):
        PairwiseSum(10, leaf=100)
    acc = PairwiseSum(3)
    acc.add([1.0, 2.0])
    with pytest.raises(ValueError, match='2 of the 3'):
        acc.total()
    with pytest.raises(ValueError, match='more than'):
        acc.add([1.0, 2.0])
