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

"""tskf_ros.core.matrices: the covariance checks against eigenvalues, the vector conversion."""

import numpy as np
import pytest

from tskf_ros.core.matrices import as_vector, FilterError, is_invertible, is_psd


def test_fast_psd_and_invertibility_checks_agree_with_eigenvalues():
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 4):
        for _ in range(200):
            M = rng.normal(size=(n, n))
            P = M @ M.T + rng.normal() * np.eye(n)     # sometimes indefinite
            lam = np.linalg.eigvalsh(P)[0]
            scale = max(1.0, np.max(np.abs(np.diag(P))))
            if abs(lam) > 1e-6 * scale:                # away from the tolerance band
                assert is_psd(P) == (lam > 0)
            A = rng.normal(size=(n, n))
            assert is_invertible(A) == (np.linalg.cond(A) < 1e10)
    singular = np.array([[1.0, 1.0], [-1.0, -1.0]])      # I + A of Example 3.20 on Z
    assert not is_invertible(singular) and not is_invertible(1e6 * singular)
    assert is_invertible(1e-6 * np.eye(3))                # scale does not matter


@pytest.mark.parametrize('value, size', [(2.5, 1), ([1.0, 2.0], 2), (np.arange(3.0), 3),
                                         (np.array([[1], [2]]), 2), ((1, 2, 3), 3)])
def test_as_vector_gives_the_float_entries(value, size):
    v = as_vector(value, size, 'y')
    assert v.dtype == np.float64 and v.shape == (size,)
    np.testing.assert_array_equal(v, np.asarray(value, dtype=float).reshape(-1))


@pytest.mark.parametrize('value, size, words', [
    (float('nan'), 1, 'non-finite'), ([1.0, float('inf')], 2, 'non-finite'),
    (1e308 * 10, 1, 'non-finite'), ([1.0, 2.0], 3, 'must have 3 entries, got 2'),
    ('abc', 1, 'not numeric'), (2.0, 2, 'must have 2 entries, got 1')])
def test_as_vector_refuses_with_the_reason(value, size, words):
    with pytest.raises(FilterError, match=words):
        as_vector(value, size, 'y')


def test_the_stacked_psd_check_is_the_one_matrix_check_for_each():
    # psd_stack over (K, n, n) against is_psd one matrix at a time, with matrices inside,
    # at and beyond the tolerance band, huge entries and NaN
    from tskf_ros.core.matrices import psd_stack
    rng = np.random.default_rng(12)
    for n in (1, 2, 3):
        stack = []
        for _ in range(300):
            M = rng.normal(size=(n, n))
            P = M @ M.T + rng.choice([-1.0, -1e-9, 0.0, 1e-9, 1.0]) * rng.random() * np.eye(n)
            stack.append(P * rng.choice([1.0, 1e-12, 1e150, 1e300]))
        stack.append(np.full((n, n), np.nan))
        stack = np.array(stack)
        np.testing.assert_array_equal(psd_stack(stack), [is_psd(P) for P in stack])
