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

"""Pathological and degenerate intervals (Fang & de Callafon 2011, Definitions 2-3)."""

from irregular_cases import pbh_detectable, ROT3, rotation
import numpy as np

from tskf_ros.core import irregular as ir


def test_eigenvalues_plus_minus_two_every_even_interval_is_pathological():
    A = np.diag([2.0, -2.0])
    assert ir.pathological_intervals(A, 10) == [2, 4, 6, 8, 10]
    # one output sees 2 and -2 summed: (A^2, C) = (4 I, [1, 1]) is not detectable
    assert ir.degenerate_intervals(A, [[1.0, 1.0]], 10) == [2, 4, 6, 8, 10]
    # C = I sees both modes: pathological but not degenerate
    assert ir.degenerate_intervals(A, np.eye(2), 10) == []


def test_rotation_by_two_thirds_pi_scaled_multiples_of_three():
    assert ir.pathological_intervals(ROT3, 12) == [3, 6, 9, 12]
    assert ir.degenerate_intervals(ROT3, [[1.0, 0.0]], 12) == [3, 6, 9, 12]
    assert ir.degenerate_intervals(ROT3, [[1.0, 0.0]], 12, criterion='detectability') == \
        [3, 6, 9, 12]
    assert ir.degenerate_intervals(ROT3, np.eye(2), 12) == []
    # A^3 = 1.331 I: a single output cannot observe it
    assert np.allclose(np.linalg.matrix_power(ROT3, 3), 1.331 * np.eye(2))


def test_unit_circle_pairs_count_by_default():
    A = np.diag([1.0, -1.0])
    assert ir.pathological_intervals(A, 6) == [2, 4, 6]
    assert ir.pathological_intervals(A, 6, marginal=False) == []      # eq. (18) as printed
    assert ir.degenerate_intervals(A, [[1.0, 1.0]], 6) == [2, 4, 6]


def test_paper_and_detectability_criteria_differ_on_a_jordan_block():
    # Jordan block at 2 and a simple -2: C sees both eigenvectors (e1, e3), not e2
    A = np.array([[2.0, 1.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, -2.0]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert ir.pathological_intervals(A, 6) == [2, 4, 6]
    assert ir.degenerate_intervals(A, C, 6) == [2, 4, 6]          # 2 x 3 block: rank 2 < 3
    assert ir.degenerate_intervals(A, C, 6, criterion='detectability') == []
    assert all(pbh_detectable(np.linalg.matrix_power(A, k), C) for k in (2, 4, 6))


def test_checks_agree_with_brute_force_on_random_similarity_transforms():
    rng = np.random.default_rng(2011)
    blocks = [rotation(np.pi / 2, 1.3), np.diag([1.3, -1.3]), rotation(2 * np.pi / 5, 1.3),
              rotation(0.7, 1.2), np.diag([0.5, 1.5])]
    checked = 0
    for _ in range(12):
        i, j = rng.choice(len(blocks), size=2, replace=False)
        J = np.zeros((4, 4))
        J[:2, :2], J[2:, 2:] = blocks[i], blocks[j]
        M = rng.standard_normal((4, 4)) + 3 * np.eye(4)
        A = M @ J @ np.linalg.inv(M)
        C = rng.standard_normal((int(rng.integers(1, 3)), 4))
        P = ir.pathological_intervals(A, 10)
        D = ir.degenerate_intervals(A, C, 10, criterion='detectability')
        lam = np.linalg.eigvals(A)
        lam = lam[np.abs(lam) >= 1 - 1e-9]
        for k in range(2, 11):
            powers = lam ** k
            merged = any(abs(powers[a] - powers[b]) <= 1e-7 * abs(powers[a])
                         for a in range(lam.size) for b in range(a + 1, lam.size))
            assert (k in P) == merged, (i, j, k)
            if merged:
                Ak = np.linalg.matrix_power(A, k)
                assert (k in D) == (not pbh_detectable(Ak, C, 1e-7)), (i, j, k)
                checked += 1
    assert checked >= 10


def test_distinct_eigenvalues_equal_scipy_linalg_eigvals():
    # numpy's eigvals (the node's path, no scipy import) against scipy.linalg.eigvals:
    # the same clusters, values equal to 1e-12 relative to ||A||
    import scipy.linalg
    rng = np.random.default_rng(7)
    cases = [ROT3, np.diag([2.0, -2.0]), np.array([[1.0, 1.0], [0.0, 1.0]]),
             rotation(0.7, 1.2)] + [rng.standard_normal((n, n)) for n in (1, 2, 3, 6, 12)]
    for A in cases:
        got = ir.distinct_eigenvalues(A)
        lam = scipy.linalg.eigvals(A)
        scale = max(1.0, float(np.linalg.norm(A, 2)))
        assert sum(e.multiplicity for e in got) == lam.size
        for e in got:
            # a Jordan block's computed members spread by ||A|| eps^(1/2): its mean vs those
            tol = 1e-12 if e.multiplicity == 1 else 1e-7
            assert np.min(np.abs(lam - e.value)) <= tol * scale, (A, e)
