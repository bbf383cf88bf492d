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
The time-scale LQR (Bohner & Wintz 2013, Section 2 and Theorem 4.1) against independent forms.

scipy's DARE / CARE, a batch least-squares optimum, closed-form scalar Riccati solutions,
the simulated closed loop, and the Kalman filter of the package (duality, Table 5).
"""

import copy

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from tskf_ros.core import LQRError, NotInvertibleError, TimeScaleKalmanFilter, TimeScaleLQR
from tskf_ros.core import time_scales

# a damped oscillator (Bohner & Wintz Example 3.20's A) with a force input
A = np.array([[0.0, 1.0], [-1.0, -2.0]])
B = np.array([[0.0], [1.0]])
Q = np.diag([1.0, 0.5])
R = np.array([[0.3]])
F = np.diag([2.0, 1.0])
# an irregular graininess: harmonic-number steps, q^Z steps and a few long ones
MU = np.r_[1.0 / np.arange(2, 9), 0.1 * 1.5 ** np.arange(5), [0.9, 0.05, 0.6]]


def regulator(**kw):
    return TimeScaleLQR(kw.get('A', A), kw.get('B', B), kw.get('Q', Q), kw.get('R', R),
                        kw.get('F', F))


def dp_step(S, mu, A=A, B=B, Q=Q, R=R):
    """Bellman's recursion for x+ = (I + mu A) x + mu B u, stage cost mu (x'Qx + u'Ru)."""
    a, b = np.eye(A.shape[0]) + mu * A, mu * B
    Lk = np.linalg.solve(mu * R + b.T @ S @ b, b.T @ S @ a)
    return mu * Q + mu * Lk.T @ R @ Lk + (a - b @ Lk).T @ S @ (a - b @ Lk), Lk


def test_one_step_of_7_is_the_discrete_equivalents_bellman_step():
    # S = S^sigma - mu S^Delta expands to the Riccati difference equation of
    # a = I + mu A, b = mu B, q = mu Q, r = mu R (doc/design/lqr.md), here in Joseph form
    lqr = regulator()
    rng = np.random.default_rng(3)
    for mu in (0.01, 0.3, 1.0, 2.5):
        W = rng.standard_normal((2, 2))
        S_sigma = W @ W.T + 0.1 * np.eye(2)
        S, L = lqr.step(S_sigma, mu)
        S_dp, L_dp = dp_step(S_sigma, mu)
        np.testing.assert_allclose(S, S_dp, rtol=1e-12, atol=1e-12 * np.abs(S_dp).max())
        np.testing.assert_allclose(L, L_dp, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize('h', [1.0, 0.5, 0.1])
def test_constant_graininess_converges_to_the_dare_of_the_discrete_equivalent(h):
    lqr = regulator()
    X = scipy.linalg.solve_discrete_are(np.eye(2) + h * A, h * B, h * Q, h * R)
    horizons = np.rint(np.array([2.0, 4.0, 8.0, 16.0, 60.0]) / h).astype(int)
    errors = [np.abs(lqr.gains(np.full(K, h)).S[0] - X).max() for K in horizons]
    assert all(a > b for a, b in zip(errors[:4], errors[1:4])), errors
    assert errors[-1] < 1e-12 * np.abs(X).max()
    # the stationary solution is that DARE, and a fixed point of (7)
    st = lqr.stationary(h)
    np.testing.assert_allclose(st.S, X, rtol=1e-12)
    np.testing.assert_allclose(lqr.step(st.S, h)[0], st.S, rtol=1e-11)
    np.testing.assert_allclose(st.L, lqr.gains(np.full(400, h)).L[0], rtol=1e-9)


def test_the_stationary_solution_tends_to_the_care_at_first_order():
    lqr = regulator()
    Xc = scipy.linalg.solve_continuous_are(A, B, Q, R)
    mus = 0.1 / 2.0 ** np.arange(6)
    errors = np.array([np.abs(lqr.stationary(mu).S - Xc).max() for mu in mus])
    ratios = errors[:-1] / errors[1:]
    # halving mu halves the error: first order (Euler's I + mu A), ever more exactly
    np.testing.assert_allclose(ratios, 2.0, atol=0.06)
    assert np.all(np.diff(np.abs(ratios - 2.0)) < 0), ratios
    np.testing.assert_allclose(lqr.stationary(0.0).S, Xc, rtol=1e-12)
    np.testing.assert_allclose(lqr.stationary(0.0).L, np.linalg.solve(R, B.T @ Xc), rtol=1e-12)


def test_a_long_dense_stretch_reaches_the_care():
    lqr = regulator()
    Xc = scipy.linalg.solve_continuous_are(A, B, Q, R)
    g = lqr.gains([40.0], dense=[True])
    np.testing.assert_allclose(g.S[0], Xc, rtol=1e-9)
    np.testing.assert_allclose(g.L[0], np.linalg.solve(R, B.T @ Xc), rtol=1e-9)
    np.testing.assert_allclose(g.S[1], F)


def test_a_dense_stretch_follows_the_closed_form_scalar_riccati_solution():
    # -s' = 2 a s - b^2 s^2 / r + q: s(t_f - tau) = s_+ + (s_+ - s_-) / (c e^{k tau} - 1),
    # roots s_+- of the right side, k = b^2 (s_+ - s_-) / r, c from s(t_f) = f
    a, b, q, r, f, T = 0.4, 1.5, 2.0, 0.7, 0.2, 3.0
    lqr = TimeScaleLQR(a, b, q, r, f)
    disc = np.sqrt(a * a + b * b * q / r)
    sp, sm = r * (a + disc) / b ** 2, r * (a - disc) / b ** 2
    k = b * b * (sp - sm) / r
    c = (f - sm) / (f - sp)

    def s(tau):
        return sp + (sp - sm) / (c * np.exp(k * tau) - 1.0)

    g = lqr.gains([T], dense=[True])
    assert g.S[0, 0, 0] == pytest.approx(s(T), rel=1e-9)
    for t in (0.0, 0.7, 1.9, 3.0):
        assert g.stretches[0](t)[0, 0] == pytest.approx(s(T - t), rel=1e-8)


def test_fine_graininess_tends_to_the_dense_stretch_at_first_order():
    lqr = regulator()
    dense = lqr.gains([2.0], dense=[True]).S[0]
    errors = np.array([np.abs(lqr.gains(np.full(n, 2.0 / n)).S[0] - dense).max()
                       for n in (50, 100, 200, 400)])
    np.testing.assert_allclose(errors[:-1] / errors[1:], 2.0, atol=0.05)


def simulate(lqr, mu, x0):
    """Run u = -L x on x^sigma = x + mu (A x + B u); return the cost (4) without the 1/2s."""
    gains = lqr.gains(mu)
    x, J = np.array(x0, dtype=float), 0.0
    for k, m in enumerate(mu):
        u = -gains.L[k] @ x
        J += m * (x @ lqr.Q @ x + u @ lqr.R @ u)
        x = x + m * (lqr.A @ x + lqr.B @ u)
    return J + x @ lqr.F @ x, gains


def batch_optimum(lqr, mu, x0):
    """Minimise the cost over the stacked inputs by least squares (no Riccati equation)."""
    n, m, K = lqr.n, lqr.m, len(mu)
    # x_k = Phi_k x0 + Gamma_k U, U = (u_0, ..., u_{K-1})
    Phi, Gamma = np.eye(n), np.zeros((n, m * K))
    rows, rhs = [], []
    for k, mk in enumerate(mu):
        Rq, Rr = np.linalg.cholesky(mk * lqr.Q + 1e-300 * np.eye(n)).T, np.sqrt(mk * lqr.R)
        rows.append(Rq @ Gamma)
        rhs.append(-Rq @ Phi @ x0)
        sel = np.zeros((m, m * K))
        sel[:, m * k:m * (k + 1)] = np.eye(m)
        rows.append(Rr @ sel)
        rhs.append(np.zeros(m))
        a = np.eye(n) + mk * lqr.A
        Phi, Gamma = a @ Phi, a @ Gamma + mk * lqr.B @ sel
    Rf = np.linalg.cholesky(lqr.F).T
    rows.append(Rf @ Gamma)
    rhs.append(-Rf @ Phi @ x0)
    M, y = np.vstack(rows), np.concatenate(rhs)
    U = np.linalg.lstsq(M, y, rcond=None)[0]
    return float(np.sum((M @ U - y) ** 2)), U


def test_realised_cost_is_x0_S0_x0_and_the_batch_optimum():
    lqr = regulator()
    x0 = np.array([1.5, -0.7])
    J, gains = simulate(lqr, MU, x0)
    assert J == pytest.approx(x0 @ gains.S[0] @ x0, rel=1e-10)
    # the least-squares optimum over all input sequences has the same cost and inputs
    J_batch, U = batch_optimum(lqr, MU, x0)
    assert J_batch == pytest.approx(J, rel=1e-9)
    x = x0.copy()
    for k, m in enumerate(MU):
        u = -gains.L[k] @ x
        assert u[0] == pytest.approx(U[k], rel=1e-7, abs=1e-10)
        x = x + m * (A @ x + B @ u)


def test_realised_cost_on_a_mixed_time_scale():
    # points, then a dense stretch [t_3, t_3 + 1.5], then points again
    mu, dense = [0.5, 0.25, 0.4, 1.5, 0.3, 0.6], [False, False, False, True, False, False]
    lqr = regulator()
    gains = lqr.gains(mu, dense)
    x0 = np.array([1.0, 2.0])
    x, J = x0.copy(), 0.0
    for k, (m, d) in enumerate(zip(mu, dense)):
        if not d:
            u = -gains.L[k] @ x
            J += m * (x @ Q @ x + u @ R @ u)
            x = x + m * (A @ x + B @ u)
            continue
        S_at = gains.stretches[k]

        def rhs(t, z):
            xs = z[:2]
            us = -np.linalg.solve(R, B.T @ S_at(t)) @ xs
            return np.r_[A @ xs + B @ us, xs @ Q @ xs + us @ R @ us]

        sol = scipy.integrate.solve_ivp(rhs, (0.0, m), np.r_[x, 0.0], method='DOP853',
                                        rtol=1e-11, atol=1e-13)
        x, J = sol.y[:2, -1], J + sol.y[2, -1]
    J += x @ F @ x
    assert J == pytest.approx(x0 @ gains.S[0] @ x0, rel=1e-7)
    assert gains.L[3] == pytest.approx(np.linalg.solve(R, B.T @ gains.S[3]))


def test_a_time_scale_object_gives_its_dense_flags():
    ts = time_scales.from_segments([('discrete', [0.0, 0.5, 1.0]), ('dense', 1.0, 2.0),
                                    ('discrete', [2.5, 3.0])], dense_step=0.25)
    lqr = regulator()
    g = lqr.gains(ts.mu()[:-1], ts.dense)
    assert g.S.shape == (len(ts), 2, 2) and set(g.stretches) == set(np.flatnonzero(ts.dense))


# ---------------------------------------------------------------------------------------
# Duality (Theorem 4.1, Table 5)


def test_the_sweep_of_the_dual_is_the_filters_covariance_reversed():
    """
    Table 5: A -> A^T, B -> C^T, Q -> G Q G^T, R -> R, S^sigma(t) <-> P(t).

    Precisely: the filter runs t_0 < ... < t_K with graininess mu_0..mu_{K-1}, and P_j is
    its predicted covariance P(t_j) (Table 3, P(t_0) = P0); the dual regulator runs on
    s_0 < ... < s_K with the reversed graininess nu_i = mu_{K-1-i} and S(s_K) = P0.  Then
    one step of (7) over nu_i is the map P(t_j) -> P(sigma(t_j)) of Table 3 at j = K-1-i,
    so S(s_i) = P(t_{K-i}): S^sigma(s_i) = P(t_j) as the table says, and the gain (8)
    of the dual is the transpose of the Kalman gain (21) at t_j.
    """
    Ak = np.array([[0.0, 1.0], [-1.0, -2.0]])
    C = np.array([[1.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    Qn, Rn, P0 = np.array([[1.0]]), np.array([[2.0]]), np.diag([2.0, 3.0])
    kf = TimeScaleKalmanFilter(Ak, C, Q=Qn, R=Rn, G=G, x0=[1.0, 1.0], P0=P0)
    P, K = [kf.P.copy()], []
    for m in MU:
        # the Kalman gain of Table 3 read off the filter: with xhat = 0, y = 1 and no
        # input, xhat(sigma) = mu K y
        probe = copy.deepcopy(kf)
        probe.set_state(np.zeros(2), kf.P)
        K.append(probe.step(m, [1.0]).x_predicted / m)
        kf.step(m, [0.3])
        P.append(kf.P.copy())
    dual = TimeScaleLQR(Ak.T, C.T, G @ Qn @ G.T, Rn, P0)
    gains = dual.gains(MU[::-1])
    scale = max(np.abs(p).max() for p in P)
    np.testing.assert_allclose(gains.S[::-1], np.array(P), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(gains.L[::-1][:, 0, :], np.array(K), rtol=1e-11, atol=1e-13)


# ---------------------------------------------------------------------------------------
# Refusals: one line, a ValueError


def one_line(excinfo):
    text = str(excinfo.value)
    assert '\n' not in text and text, text
    assert isinstance(excinfo.value, ValueError)
    return text


@pytest.mark.parametrize('kw, match', [
    ({'Q': [[1.0, 0.3], [0.0, 1.0]]}, 'Q is not symmetric'),
    ({'F': [[1.0, 0.0], [0.0, -0.5]]}, 'F is indefinite'),
    ({'R': [[-0.1]]}, 'R is indefinite'),
    ({'Q': [[np.nan, 0.0], [0.0, 1.0]]}, 'Q has non-finite'),
    ({'B': [[1.0], [0.0], [0.0]]}, 'B must have 2 rows'),
    ({'R': np.eye(2)}, r'R must have shape \(1, 1\)'),
    ({'A': np.ones((2, 3))}, 'A must be square'),
])
def test_bad_models_are_refused(kw, match):
    with pytest.raises(LQRError, match=match) as excinfo:
        regulator(**kw)
    one_line(excinfo)


@pytest.mark.parametrize('mu, dense, match', [
    ([0.5, -0.1], None, r'mu\[1\] = -0\.1'),
    ([0.5, np.nan], None, 'finite'),
    ([0.5, 0.0], None, 'right-dense point'),
    ([0.5, 0.0], [False, True], 'length > 0'),
    ([0.5, 1.0], [True], 'one flag per step'),
    ([], None, 'empty'),
    ('abc', None, 'sequence of numbers'),
])
def test_bad_time_scales_are_refused(mu, dense, match):
    with pytest.raises(LQRError, match=match) as excinfo:
        regulator().gains(mu, dense)
    one_line(excinfo)


def test_theorem_2_17_is_the_boundary_not_r_positive_definite():
    # R = 0 is allowed where R + mu B^T S^sigma B is invertible (F weighs what B moves) ...
    lqr = regulator(R=[[0.0]], F=np.eye(2))
    g = lqr.gains([0.5, 0.5])
    assert np.all(np.isfinite(g.L))
    # ... and refused at the first point where it is not (S(t_f) = F = 0)
    with pytest.raises(NotInvertibleError, match=r'at t_1 .*Theorem 2\.17') as excinfo:
        regulator(R=[[0.0]], F=np.zeros((2, 2))).gains([0.5, 0.5])
    one_line(excinfo)
    # a dense stretch has R^-1 in it
    with pytest.raises(LQRError, match='positive definite') as excinfo:
        lqr.gains([1.0], dense=[True])
    one_line(excinfo)


def test_no_stationary_solution_is_refused():
    # an unstable mode that B cannot move
    lqr = TimeScaleLQR(np.diag([1.0, -1.0]), [[0.0], [1.0]], np.eye(2), [[1.0]])
    for mu in (0.0, 0.5):
        with pytest.raises(LQRError, match='no stationary solution') as excinfo:
            lqr.stationary(mu)
        one_line(excinfo)
    with pytest.raises(LQRError, match='finite and >= 0') as excinfo:
        lqr.stationary(-1.0)
    one_line(excinfo)


def test_one_step_needs_a_right_scattered_point_and_a_stretch_a_length():
    for mu in (0.0, -1.0, np.inf):
        with pytest.raises(LQRError, match='finite mu > 0') as excinfo:
            regulator().step(F, mu)
        one_line(excinfo)
        with pytest.raises(LQRError, match='finite length > 0') as excinfo:
            regulator().integrate(F, mu)
        one_line(excinfo)


def test_gains_unpack_as_s_and_l():
    lqr = TimeScaleLQR([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], np.eye(2), [[1.0]], np.eye(2))
    S, L = lqr.gains([0.5, 0.25, 1.0])
    assert S.shape == (4, 2, 2) and L.shape == (3, 1, 2)
    # the last gain is (8) at t_2 from S(t_f) = F: (R + mu B^T F B)^-1 B^T F (I + mu A)
    mu, A, B, F = 1.0, np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.eye(2)
    want = np.linalg.solve(np.eye(1) + mu * B.T @ F @ B, B.T @ F @ (np.eye(2) + mu * A))
    np.testing.assert_allclose(L[-1], want, rtol=1e-12)
