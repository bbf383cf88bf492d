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

"""The switching filter (13)-(17) equals the lifted filter (3)-(8) at the sampling instants."""

import numpy as np
import pytest

from tskf_ros.core import irregular as ir


def test_lifted_equals_switching_with_input_at_the_sampling_instants():
    rng = np.random.default_rng(13)
    n = 3
    A = rng.standard_normal((n, n)) * 0.6 + np.eye(n) * 0.4
    B = rng.standard_normal((n, 2))
    C = rng.standard_normal((1, n))
    G = rng.standard_normal((n, n))
    Q, R = G @ G.T * 0.1, np.array([[0.5]])
    N = 40
    times = np.concatenate([[0], np.cumsum(rng.integers(1, 6, size=12))])
    times = times[times < N]
    u = rng.standard_normal((N, 2))
    y = np.full((N, 1), np.nan)
    y[times, 0] = rng.standard_normal(times.size)
    x0, P0 = rng.standard_normal(n), np.eye(n) * 2.0
    sw = ir.run_switching(A, C, Q=Q, R=R, x0=x0, P0=P0, y=y, B=B, u=u)
    li = ir.run_lifted(A, C, Q=Q, R=R, x0=x0, P0=P0, times=times, y=y[times], B=B, u=u)
    for a, b in ((sw.x_prior[times], li.x_prior), (sw.P_prior[times], li.P_prior),
                 (sw.x_post[times], li.x_post), (sw.P_post[times], li.P_post)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    # between samples the switching filter only predicts: (11)-(12)
    gap = np.setdiff1d(np.arange(N), times)
    np.testing.assert_array_equal(sw.x_post[gap], sw.x_prior[gap])


def test_lifted_hand_numbers():
    # a = 2, c = q = r = 1, P_0^- = 1: P_0^+ = 1/2; over kappa = 2: 16/2 + (4 + 1) = 13
    li = ir.run_lifted([[2.0]], [[1.0]], Q=[[1.0]], R=[[1.0]], x0=[0.0], P0=[[1.0]],
                       times=[0, 2], y=[[1.0], [4.0]], B=[[1.0]], u=[[1.0], [0.5]])
    assert li.P_post[0, 0, 0] == pytest.approx(0.5)
    assert li.P_prior[1, 0, 0] == pytest.approx(13.0)
    # x_0^+ = 0.5; x_2^- = 4 * 0.5 + [2, 1] [1, 0.5] = 4.5; K = 13 / 14
    assert li.x_prior[1, 0] == pytest.approx(4.5)
    assert li.x_post[1, 0] == pytest.approx(4.5 - 0.5 * 13 / 14)
    Phi, Gamma, Omega = ir.lifted_matrices([[2.0]], [[1.0]], 3)
    np.testing.assert_array_equal(Phi, [[8.0]])
    np.testing.assert_array_equal(Gamma, [[4.0, 2.0, 1.0]])
    np.testing.assert_array_equal(Omega, [[4.0, 2.0, 1.0]])
