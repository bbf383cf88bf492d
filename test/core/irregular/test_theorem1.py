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

"""Theorem 1, Corollaries 1-2 and the interval warnings (Fang & de Callafon 2011)."""

from irregular_cases import pbh_detectable, ROT3, rotation
import numpy as np

from tskf_ros.core import irregular as ir


def test_theorem1_and_interval_warnings_for_the_rotation():
    C = [[1.0, 0.0]]
    ok = ir.theorem1(ROT3, C, [1, 2, 4, 5, 7])
    assert ok.stable and ok.pathological == () and ok.detectable
    bad = ir.theorem1(ROT3, C, [1, 3, 4])
    assert not bad.stable and bad.degenerate == (3,) and bad.pathological == (3,)
    both = ir.theorem1(ROT3, np.eye(2), [1, 3, 6])
    assert both.stable and both.pathological == (3, 6) and both.degenerate == ()
    warnings = ir.interval_warnings(ROT3, C, [2, 3, 6, 1])
    assert [k for k, _ in warnings] == [3, 6]
    assert all(reason.startswith('degenerate') for _, reason in warnings)
    assert '1.1*exp(+2.0944j)' in warnings[0][1]
    (k, reason), = ir.interval_warnings(ROT3, np.eye(2), [3])
    assert k == 3 and reason.startswith('pathological') and 'not degenerate' in reason
    assert ir.interval_warnings(ROT3, C, [1, 2, 4]) == []
    # an undetectable pair is flagged at every interval
    assert ir.interval_warnings(np.diag([2.0, 0.5]), [[0.0, 1.0]], [1])[0][0] == 1


def test_theorem1_is_not_stable_without_detectability():
    # (A1) fails: the unstable mode 2 is invisible to C = [0, 1]; with a single unstable
    # eigenvalue no interval is pathological, so T n D = {} and only (A1) says 'unstable'
    A, C = np.diag([2.0, 0.5]), [[0.0, 1.0]]
    assert not pbh_detectable(A, np.array(C))
    check = ir.theorem1(A, C, [1, 2, 3])
    assert check.degenerate == () and check.pathological == ()
    assert not check.detectable and not check.stable
    # the switching filter confirms it: the peak covariance of the hidden mode grows as 4^k
    y = np.zeros((12, 1))
    sw = ir.run_switching(A, C, Q=np.eye(2), R=[[1.0]], x0=[0.0, 0.0], P0=np.eye(2), y=y)
    p = sw.P_prior[:, 0, 0]
    np.testing.assert_allclose(p[1:], 4 * p[:-1] + 1, rtol=1e-12)
    # and with C seeing it, the same intervals are fine
    assert ir.theorem1(A, [[1.0, 1.0]], [1, 2, 3]).stable


def test_stable_modes_never_pathological_and_corollaries():
    # the drogue: one double eigenvalue 1 (a Jordan block), nothing to merge
    A_drogue = [[1.0, 5.0], [0.0, 1.0]]
    assert ir.distinct_eigenvalues(A_drogue) == [ir.Eigenvalue(1 + 0j, 2)]
    assert ir.pathological_intervals(A_drogue, 500) == []
    assert ir.corollary1(A_drogue) and ir.corollary2(A_drogue, [[1.0, 0.0]])
    assert ir.is_detectable(A_drogue, [[1.0, 0.0]])
    assert not ir.is_detectable(A_drogue, [[0.0, 1.0]])
    assert ir.pathological_intervals(rotation(2 * np.pi / 3, 0.9), 12) == []
    assert not ir.corollary1(ROT3)
    assert ir.corollary2(ROT3, np.eye(2)) and not ir.corollary2(ROT3, [[1.0, 0.0]])
    # Corollary 1 is only sufficient: an irrational angle fails it, yet P is empty
    irr = rotation(1.0, 1.1)
    assert not ir.corollary1(irr) and ir.pathological_intervals(irr, 60) == []
