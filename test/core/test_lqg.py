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
The time-scale LQG of Remark 4.2 (Bohner & Wintz 2013): separation (31) and its cost (29).

The closed loop is probed through the controller's own code; the expected cost is checked
against a seeded Monte Carlo of the simulated plant.
"""

import copy

import numpy as np
import pytest

from tskf_ros.core import LQRError, TimeScaleLQG, TimeScaleLQR

A = np.array([[0.0, 1.0], [-1.0, -0.5]])
B = np.array([[0.0], [1.0]])
C = np.array([[1.0, 0.0]])
G = np.array([[0.0], [1.0]])
M, N, F = np.diag([1.0, 0.2]), np.array([[0.5]]), np.eye(2)
Qn, Rn = np.array([[0.4]]), np.array([[0.3]])
X0, P0 = np.array([1.0, -0.5]), np.diag([0.5, 0.2])
MU = np.array([0.5, 1.0, 0.25, 0.5, 0.75, 1.0, 0.5, 0.3, 0.6, 0.4])


def controller(mu=MU, estimate='predicted', **kw):
    args = {'M': M, 'N': N, 'F': F, 'Q': Qn, 'R': Rn, 'G': G, 'x0': X0, 'P0': P0}
    args.update(kw)
    return TimeScaleLQG(A, B, C, mu=mu, estimate=estimate, **args)


@pytest.mark.parametrize('estimate', ['predicted', 'corrected'])
def test_closed_loop_eigenvalues_separate(estimate):
    """
    (31) at a constant mu: [x, xtilde]^Delta = [[A - B L, B L], [0, A - K C]] [x, xtilde].

    Its discrete equivalent is I + mu times that matrix (Theorem 2.5d), block triangular,
    so the closed loop's eigenvalues are 1 + mu eig(A - B L) and 1 + mu eig(A - K C):
    those of (I + mu A) - mu B L and (I + mu A) - mu K C, with L the stationary gain (8)
    and K the stationary Kalman gain (21), here the dual regulator's gain transposed
    (Table 5).  Feeding back x(t|t) instead, the error moves by (I + mu A)(I - K_f C),
    whose eigenvalues are those of (I + mu A) - mu K C again (mu K = (I + mu A) K_f).
    """
    mu = 0.4
    lqg = controller(mu=np.full(300, mu), estimate=estimate)
    for _ in range(150):          # to the middle: both gains stationary to rounding
        lqg.step(C @ X0)
    n = 2
    T = np.empty((2 * n, 2 * n))
    for i in range(2 * n):
        z = np.eye(2 * n)[i]
        probe = copy.deepcopy(lqg)
        probe.filter.set_state(z[n:], probe.filter.P)
        x = z[:n]
        u = probe.step(C @ x)
        T[:, i] = np.r_[x + mu * (A @ x + B @ u), probe.filter.x]
    L = TimeScaleLQR(A, B, M, N).stationary(mu).L
    K = TimeScaleLQR(A.T, C.T, G @ Qn @ G.T, Rn).stationary(mu).L.T
    want = np.r_[1 + mu * np.linalg.eigvals(A - B @ L), 1 + mu * np.linalg.eigvals(A - K @ C)]
    got = np.linalg.eigvals(T)
    np.testing.assert_allclose(np.sort_complex(got), np.sort_complex(want), atol=1e-10)
    # and the designs are stable: every eigenvalue inside the unit circle
    assert np.all(np.abs(got) < 1)


@pytest.mark.parametrize('estimate', ['predicted', 'corrected'])
def test_monte_carlo_cost_matches_the_expected_cost(estimate):
    # x^sigma = x + mu (A x + B u) + mu G w with Var(mu G w) = mu G Q G^T (Table 3's
    # Q_d), y = C x + v with Var v = R / mu (its R_d), x0 ~ N(X0, P0): the model the
    # filter is optimal for, so E[J] is the value from the sweep and the covariances
    lqg = controller(estimate=estimate)
    runs, K = 1500, MU.size
    rng = np.random.default_rng(2013)
    x0 = rng.multivariate_normal(X0, P0, size=runs)
    w = rng.standard_normal((runs, K)) * np.sqrt(Qn[0, 0])
    v = rng.standard_normal((runs, K)) * np.sqrt(Rn[0, 0] / MU)
    J = np.empty(runs)
    for r in range(runs):
        lqg.reset()
        x, cost = x0[r], 0.0
        for k, mu in enumerate(MU):
            u = lqg.step(C @ x + v[r, k])
            cost += mu * (x @ M @ x + u @ N @ u)
            x = x + mu * (A @ x + B @ u) + np.sqrt(mu) * G[:, 0] * w[r, k]
        J[r] = (cost + x @ F @ x) / 2
    se = J.std(ddof=1) / np.sqrt(runs)
    assert abs(J.mean() - lqg.expected_cost()) < 3 * se, (J.mean(), lqg.expected_cost(), se)


def test_noise_free_loop_is_the_lqr():
    # Q = 0 and P0 = 0: the estimate is exact, u = -L x, J = 1/2 x0^T S(t_0) x0
    lqg = controller(Q=[[0.0]], P0=np.zeros((2, 2)))
    S0 = lqg.plan.S[0]
    assert lqg.expected_cost() == pytest.approx(X0 @ S0 @ X0 / 2, rel=1e-12)
    x, cost = X0.copy(), 0.0
    for mu in MU:
        u = lqg.step(C @ x)
        cost += mu * (x @ M @ x + u @ N @ u)
        x = x + mu * (A @ x + B @ u)
    assert (cost + x @ F @ x) / 2 == pytest.approx(X0 @ S0 @ X0 / 2, rel=1e-10)


def test_bad_uses_are_refused():
    with pytest.raises(LQRError, match='estimate must be one of'):
        controller(estimate='smoothed')
    with pytest.raises(LQRError, match='right-dense point'):
        controller(mu=[0.5, 0.0])
    lqg = controller(mu=[0.5])
    lqg.step([0.0])
    with pytest.raises(LQRError, match='all are used') as excinfo:
        lqg.step([0.0])
    assert '\n' not in str(excinfo.value)
