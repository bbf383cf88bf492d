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
TimeScaleKalmanFilter against formulations written independently here.

`step` at every size against Bohner & Wintz Table 3 written out term by term in plain numpy
(the sampled plant for the exact transition), with the corrected estimate of the discrete
filter (R_d = R / mu, Joseph form), to 1e-12 relative.  Relative to what: the norm of the
quantity plus the norm of the prior it is computed from (x or P), since a corrected
covariance much smaller than the prior carries the rounding of the prior.  Random models at
n = 1, 2, 3, 6, 20, 50, every p = 1..n, with and without an input, Euler and exact
transitions, and gaps (y = None).  Also the textbook predictive filter, Table 1 at mu = 1,
the DARE and CARE limits, and the Kalman-Bucy filter of Table 2 against closed forms.
"""

import numpy as np
import pytest
import scipy.linalg

from tskf_ros.core.matrices import FilterError
from tskf_ros.core.timescale_kalman import (InnovationTest, NonRegressiveError,
                                            TimeScaleKalmanFilter)


RTOL = 1e-12
SIZES = (1, 2, 3, 6, 20, 50)


def textbook_model(rng, n=3, p=2, r=2):
    """Draw a random stable-ish model with SPD covariances (3 states, 2 outputs, 1 input)."""
    A = rng.normal(size=(n, n)) * 0.5 - np.eye(n)
    C = rng.normal(size=(p, n))
    G = rng.normal(size=(n, r))
    Mq = rng.normal(size=(r, r))
    Mr = rng.normal(size=(p, p))
    Q = Mq @ Mq.T + 0.1 * np.eye(r)
    R = Mr @ Mr.T + 0.5 * np.eye(p)
    B = rng.normal(size=(n, 1))
    D = rng.normal(size=p)
    x0 = rng.normal(size=n)
    M0 = rng.normal(size=(n, n))
    P0 = M0 @ M0.T + np.eye(n)
    return {'A': A, 'C': C, 'G': G, 'Q': Q, 'R': R, 'B': B, 'D': D, 'x0': x0, 'P0': P0}


def random_model(rng, n, p, m):
    """Return a stable random model with SPD covariances; m inputs (0: no B)."""
    A = rng.normal(size=(n, n)) * 0.5 / np.sqrt(n) - 0.3 * np.eye(n)
    r = max(1, n // 2)
    G = rng.normal(size=(n, r))
    Mq, Mr, M0 = rng.normal(size=(r, r)), rng.normal(size=(p, p)), rng.normal(size=(n, n))
    model = {'A': A, 'C': rng.normal(size=(p, n)), 'G': G, 'Q': Mq @ Mq.T + 0.1 * np.eye(r),
             'R': Mr @ Mr.T + 0.5 * np.eye(p), 'D': rng.normal(size=p),
             'x0': rng.normal(size=n), 'P0': M0 @ M0.T + np.eye(n)}
    if m:
        model['B'] = rng.normal(size=(n, m))
    return model


def textbook_predictive_step(x, P, y, u, mu, m):
    """Predictive discrete KF with F = I + mu A, Q_d = mu GQG^T, R_d = R / mu (one step)."""
    F = np.eye(len(x)) + mu * m['A']
    Qd = mu * m['G'] @ m['Q'] @ m['G'].T
    Rd = m['R'] / mu
    S = m['C'] @ P @ m['C'].T + Rd
    Kd = F @ P @ m['C'].T @ np.linalg.inv(S)
    x_next = F @ x + mu * m['B'] @ u + Kd @ (y - m['C'] @ x - m['D'])
    P_next = F @ P @ F.T - Kd @ S @ Kd.T + Qd
    return x_next, P_next


def test_step_equals_textbook_predictive_filter_at_every_mu():
    rng = np.random.default_rng(0)
    m = textbook_model(rng)
    kf = TimeScaleKalmanFilter(**m)
    x, P = m['x0'].copy(), m['P0'].copy()
    for mu in [0.01, 0.3, 1.0, 2.0, 0.05, 4.0, 1e-4, 0.7]:
        y = rng.normal(size=2)
        u = rng.normal(size=1)
        kf.step(mu, y, u)
        x, P = textbook_predictive_step(x, P, y, u, mu, m)
        np.testing.assert_allclose(kf.x, x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(kf.P, P, rtol=1e-9, atol=1e-9)


def test_corrected_estimate_is_the_measurement_update():
    rng = np.random.default_rng(1)
    m = textbook_model(rng)
    kf = TimeScaleKalmanFilter(**m)
    for mu in [0.5, 2.0, 0.1]:
        x, P = kf.x.copy(), kf.P.copy()
        y = rng.normal(size=2)
        kf.step(mu, y)
        S = m['C'] @ P @ m['C'].T + m['R'] / mu
        L = P @ m['C'].T @ np.linalg.inv(S)
        np.testing.assert_allclose(kf.x_corrected, x + L @ (y - m['C'] @ x - m['D']),
                                   atol=1e-10)
        np.testing.assert_allclose(kf.P_corrected, P - L @ S @ L.T, atol=1e-10)
        # the predictor is the corrected estimate pushed through I + mu A
        F = np.eye(3) + mu * m['A']
        np.testing.assert_allclose(kf.x, F @ kf.x_corrected, atol=1e-9)
        np.testing.assert_allclose(kf.P, F @ kf.P_corrected @ F.T
                                   + mu * m['G'] @ m['Q'] @ m['G'].T, atol=1e-9)


def test_mu_one_is_bohner_wintz_table_1():
    # Table 1: x(t+1) = Ad x + Ad P C^T (R + C P C^T)^-1 (y - C x),
    # P(t+1) = Ad P Ad^T - Ad P C^T (R + C P C^T)^-1 C P Ad^T + GQG^T, with Ad = I + A.
    # (Example 3.20's A has I + A singular, so a regressive variant is used here.)
    A = np.array([[0.0, 1.0], [-2.0, -2.0]])
    Ad = np.eye(2) + A
    C = np.array([[1.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    Q, R = np.array([[1.0]]), np.array([[2.0]])
    kf = TimeScaleKalmanFilter(A, C, Q=Q, R=R, G=G, x0=[1, 1], P0=np.diag([2.0, 3.0]))
    x, P = np.array([1.0, 1.0]), np.diag([2.0, 3.0])
    for y in [0.3, -1.2, 2.5, 0.0, 1.1]:
        K = Ad @ P @ C.T @ np.linalg.inv(R + C @ P @ C.T)
        x = Ad @ x + K @ (np.array([y]) - C @ x)
        P = Ad @ P @ Ad.T - K @ C @ P @ Ad.T + G @ Q @ G.T
        kf.step(1.0, y)
        np.testing.assert_allclose(kf.x, x, atol=1e-12)
        np.testing.assert_allclose(kf.P, P, atol=1e-12)


def test_dare_fixed_point_and_limit_to_care_as_mu_goes_to_zero():
    A = np.array([[0.0, 1.0], [-1.0, -2.0]])
    C = np.array([[1.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    Q, R = np.array([[1.0]]), np.array([[2.0]])
    P_care = scipy.linalg.solve_continuous_are(A.T, C.T, G @ Q @ G.T, R)
    errors = []
    for mu in [0.1, 0.01, 0.001]:
        F = np.eye(2) + mu * A
        P_dare = scipy.linalg.solve_discrete_are(F.T, C.T, mu * G @ Q @ G.T, R / mu)
        kf = TimeScaleKalmanFilter(A, C, Q=Q, R=R, G=G, x0=[0, 0], P0=P_dare)
        kf.step(mu, 0.0)
        # the steady covariance of the discrete equivalent is a fixed point of Table 3
        np.testing.assert_allclose(kf.P, P_dare, rtol=1e-8, atol=1e-12)
        errors.append(np.max(np.abs(kf.P - P_care)))
    # first-order convergence: the error falls about tenfold per decade of mu
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 2e-3 * np.max(np.abs(P_care))
    assert 5 < errors[1] / errors[2] < 20
    # README: 'error max abs 0.041, 0.0037, 0.00037 for mu = 0.1, 0.01, 0.001'
    for got, want in zip(errors, [0.041, 0.0037, 0.00037]):
        assert got == pytest.approx(want, abs=want / 82)      # half a unit of the 2nd digit


def test_steady_state_of_the_filter_itself_tends_to_care():
    # the same limit reached by stepping the filter from P0 (no DARE solver): mu = 0.1
    A = np.array([[0.0, 1.0], [-1.0, -2.0]])
    C = np.array([[1.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    P_care = scipy.linalg.solve_continuous_are(A.T, C.T, G @ G.T, np.array([[2.0]]))
    kf = TimeScaleKalmanFilter(A, C, Q=1.0, R=2.0, G=G, x0=[0, 0], P0=np.diag([2.0, 3.0]))
    for _ in range(400):
        kf.step(0.1, 0.0)
    assert np.max(np.abs(kf.P - P_care)) == pytest.approx(0.041, abs=5e-4)


def scalar_riccati_closed_form(t, a, c, g2q, r, p0):
    """Solve p' = 2 a p + g2q - c^2 p^2 / r: p = (p+ - p- k e^{-gt}) / (1 - k e^{-gt})."""
    s = c * c / r
    disc = np.sqrt(a * a + s * g2q)
    p_plus, p_minus = (a + disc) / s, (a - disc) / s
    gamma = s * (p_plus - p_minus)
    k = (p0 - p_plus) / (p0 - p_minus)
    e = k * np.exp(-gamma * t)
    return (p_plus - p_minus * e) / (1 - e)


def test_kalman_bucy_covariance_matches_closed_form():
    a, c, q, r, p0 = -0.7, 2.0, 1.5, 0.4, 3.0
    kf = TimeScaleKalmanFilter(a, c, Q=q, R=r, x0=0.0, P0=p0)
    t = 0.0
    for dt in [0.05, 0.2, 1.0, 3.0]:
        kf.integrate(dt, y=lambda s: 0.0)
        t += dt
        assert kf.P[0, 0] == pytest.approx(scalar_riccati_closed_form(t, a, c, q, r, p0),
                                           rel=1e-8)


def test_kalman_bucy_state_at_steady_gain_matches_matrix_exponential():
    A = np.array([[0.0, 1.0], [-1.0, -2.0]])
    C = np.array([[1.0, 0.0]])
    G = np.array([[0.0], [1.0]])
    Q, R = np.array([[1.0]]), np.array([[2.0]])
    P = scipy.linalg.solve_continuous_are(A.T, C.T, G @ Q @ G.T, R)
    K = P @ C.T @ np.linalg.inv(R)
    x0, y0, T = np.array([1.0, -0.5]), 0.8, 2.5
    kf = TimeScaleKalmanFilter(A, C, Q=Q, R=R, G=G, x0=x0, P0=P)
    kf.integrate(T, y=lambda s: [y0])
    # xhat' = (A - KC) xhat + K y0: affine ODE, solved with the augmented exponential
    M = np.zeros((3, 3))
    M[:2, :2] = A - K @ C
    M[:2, 2] = (K * y0).ravel()
    expected = (scipy.linalg.expm(M * T) @ np.append(x0, 1.0))[:2]
    np.testing.assert_allclose(kf.x, expected, atol=1e-8)
    np.testing.assert_allclose(kf.P, P, atol=1e-9)


def test_missing_measurement_is_a_pure_time_update():
    A, C = np.array([[0.2]]), np.array([[1.0]])
    kf = TimeScaleKalmanFilter(A, C, Q=1.0, R=1.0, x0=2.0, P0=0.5)
    kf.step(0.5, None)
    assert kf.x[0] == pytest.approx(2.0 * 1.1)
    assert kf.P[0, 0] == pytest.approx(1.1 ** 2 * 0.5 + 0.5)


def test_scalars_and_nested_lists_are_accepted_and_shapes_are_canonical():
    kf = TimeScaleKalmanFilter([[0, 1], [-1, -2]], [1, 0], Q=1, R=2, G=[0, 1],
                               x0=[1, 1], P0=[[2, 0], [0, 3]])
    assert kf.x.shape == (2,) and kf.P.shape == (2, 2)
    assert kf.G.shape == (2, 1) and kf.C.shape == (1, 2)
    kf.step(2.0, 0.5)
    assert kf.x.shape == (2,) and kf.P.shape == (2, 2)


@pytest.mark.parametrize('kwargs, message', [
    ({'A': np.eye(2), 'C': [[1, 0, 0]]}, 'C must have 2 columns'),
    ({'A': np.ones((2, 3)), 'C': [[1, 0, 0]]}, 'A must be square'),
    ({'P0': [[1, 0.5], [0.0, 1]]}, 'P0 is not symmetric'),
    ({'P0': [[1, 2], [2, 1]]}, 'P0 is indefinite'),
    ({'Q': [[-1.0]]}, 'Q is indefinite'),
    ({'R': 0.0}, 'R must be positive definite'),
    ({'R': [[1, 0], [0, 1]]}, 'R must have shape'),
    ({'x0': [1, 2, 3]}, 'x0 must have 2 entries'),
    ({'G': [1, 0, 0]}, 'G must have 2 rows'),
    ({'transition': 'rk4'}, 'transition must be one of'),
])
def test_bad_models_are_refused_with_a_named_reason(kwargs, message):
    base = {'A': [[0, 1], [-1, -2]], 'C': [[1, 0]], 'Q': 1.0, 'R': 2.0, 'G': [0, 1],
            'x0': [1, 1], 'P0': np.diag([2.0, 3.0])}
    base.update(kwargs)
    A, C = base.pop('A'), base.pop('C')
    with pytest.raises(FilterError, match=message):
        TimeScaleKalmanFilter(A, C, **base)


def test_bad_steps_are_refused_and_leave_the_state_unchanged():
    kf = TimeScaleKalmanFilter(-1.0, 1.0, Q=1.0, R=1.0, x0=0.3, P0=1.0)
    x, P = kf.state()
    with pytest.raises(FilterError, match='mu must be >= 0'):
        kf.step(-0.1, 1.0)
    with pytest.raises(FilterError, match='right-dense'):
        kf.step(0.0, 1.0)
    with pytest.raises(FilterError, match='non-finite'):
        kf.step(0.5, float('nan'))
    with pytest.raises(FilterError, match='non-finite'):
        kf.step(0.5, float('inf'))
    with pytest.raises(FilterError, match='not regressive'):
        kf.step(1.0, 1.0)          # I + mu A = 0
    spring = TimeScaleKalmanFilter([[0, 1], [-1, -2]], [1, 0], Q=1, R=2, G=[0, 1], x0=[1, 1],
                                   P0=np.diag([2.0, 3.0]))
    with pytest.raises(FilterError, match='not regressive'):
        spring.step(1.0, 0.0)      # Example 3.20 on Z: I + A = [[1, 1], [-1, -1]]
    np.testing.assert_array_equal(kf.x, x)
    np.testing.assert_array_equal(kf.P, P)


def exact_matrices(A, GQGt, B, mu):
    """F = e^{A mu}, Q_d and B_d from one block exponential each (mu short here)."""
    n = A.shape[0]
    M = np.block([[-A, GQGt], [np.zeros((n, n)), A.T]]) * mu
    E = scipy.linalg.expm(M)
    F = E[n:, n:].T
    Qd = F @ E[:n, n:]
    k = B.shape[1]
    Bd = scipy.linalg.expm(np.block([[A, B], [np.zeros((k, n + k))]]) * mu)[:n, n:]
    return F, (Qd + Qd.T) / 2, Bd


def table_3(m, x, P, mu, y, u, transition, sampled=None):
    """
    One step, Table 3 term by term (Euler) or the sampled plant (exact); textbook inv.

    sampled: the exact (F, Q_d, B_d) to use (the filter's own, checked against
    exact_matrices by the caller to 1e-10: two exponentials differ by more than 1e-12).
    """
    A, C, R = m['A'], m['C'], m['R']
    n = A.shape[0]
    B = m.get('B', np.zeros((n, 1)))
    u = np.zeros(B.shape[1]) if u is None else u
    GQGt = m['G'] @ m['Q'] @ m['G'].T
    eye = np.eye(n)
    if transition == 'euler':
        F, Qd, Bd = eye + mu * A, mu * GQGt, mu * B
    else:
        F, Qd, Bd = sampled
    if y is None:
        return x, P, F @ x + Bd @ u, F @ P @ F.T + Qd
    e = y - C @ x - m['D']
    # corrected estimate: L = P C^T (C P C^T + R / mu)^-1, Joseph form
    Rd = R / mu
    L = P @ C.T @ np.linalg.inv(C @ P @ C.T + Rd)
    x_c = x + L @ e
    P_c = (eye - L @ C) @ P @ (eye - L @ C).T + L @ Rd @ L.T
    if transition == 'exact':
        return x_c, P_c, F @ x_c + Bd @ u, F @ P_c @ F.T + Qd
    # K = (I + mu A) P C^T (R + mu C P C^T)^-1
    K = (eye + mu * A) @ P @ C.T @ np.linalg.inv(R + mu * C @ P @ C.T)
    x_delta = A @ x + B @ u + K @ e
    P_delta = (A @ P + (eye + mu * A) @ P @ A.T + GQGt
               - K @ C @ P @ (eye + mu * A).T)
    return x_c, P_c, x + mu * x_delta, P + mu * P_delta


def close(got, want, prior):
    """Tell whether |got - want| <= RTOL (|want| + |prior|) (Frobenius norms)."""
    scale = np.linalg.norm(want) + np.linalg.norm(prior)
    return np.linalg.norm(np.asarray(got) - want) <= RTOL * scale


def cases():
    for n in SIZES:
        for p in range(1, n + 1):
            yield n, p


@pytest.mark.parametrize('transition', ['euler', 'exact'])
@pytest.mark.parametrize('m_inputs', [0, 2])
def test_every_size_equals_table_3_written_out(transition, m_inputs):
    rng = np.random.default_rng(17 + m_inputs)
    for n, p in cases():
        if n == 50 and p % 7 and p not in (1, 2, 50):
            continue            # p = 1, 2, 7, 14, .., 49, 50 at n = 50: the same code path
        m = random_model(rng, n, p, m_inputs)
        kf = TimeScaleKalmanFilter(**m, transition=transition)
        for k, mu in enumerate((0.01, 0.3, 1.0, 0.07)):
            x, P = kf.x.copy(), kf.P.copy()
            y = None if k == 2 else rng.normal(size=p) * 3       # one gap
            u = rng.normal(size=m_inputs) if m_inputs and k != 1 else None
            sampled = None
            if transition == 'exact':
                sampled = kf.transition_matrices(mu)
                B = m.get('B', np.zeros((n, 1)))
                for got, want in zip(sampled, exact_matrices(m['A'], m['G'] @ m['Q'] @ m['G'].T,
                                                             B, mu)):
                    assert np.linalg.norm(got - want) <= 1e-10 * np.linalg.norm(want)
            res = kf.step(mu, y, u)
            x_c, P_c, x_n, P_n = table_3(m, x, P, mu, y, u, transition, sampled)
            what = f'n={n} p={p} mu={mu} {transition} u={u is not None} y={y is not None}'
            assert close(res.x_corrected, x_c, x), what
            assert close(res.P_corrected, P_c, P), what
            assert close(res.x_predicted, x_n, x), what
            assert close(res.P_predicted, P_n, P), what
            assert close(kf.x, x_n, x) and close(kf.P, P_n, P), what
            np.testing.assert_array_equal(kf.P, kf.P.T)
            if y is None:
                assert np.isnan(res.innovation).all() and np.isnan(res.S).all()
            else:
                e = y - m['C'] @ x - m['D']
                assert close(res.innovation, e, y)
                S = m['C'] @ P @ m['C'].T + m['R'] / mu
                assert close(res.S, S, P)
            assert res.x_predicted.shape == (n,) and res.P_corrected.shape == (n, n)


@pytest.mark.parametrize('n', [1, 2, 3])
def test_inputs_in_every_accepted_form_give_the_same_step(n):
    rng = np.random.default_rng(n)
    m = random_model(rng, n, 1, 1)
    ys = [0.7, [0.7], np.array([0.7]), np.array([[0.7]]), np.float64(0.7)]
    us = [None, 0.0, [0.0], np.zeros(1)]
    want = None
    for y in ys:
        for u in us:
            res = TimeScaleKalmanFilter(**m).step(np.float64(0.5), y, u)
            got = (res.x_corrected, res.P_corrected, res.x_predicted, res.P_predicted)
            if want is None:
                want = got
            for a, b in zip(got, want):
                np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize('n', [1, 2, 3])
@pytest.mark.parametrize('bad_y, message', [
    (float('nan'), 'non-finite'), ([np.inf], 'non-finite'), (np.array([-np.inf]), 'non-finite'),
    ('x', 'not numeric'), ([1.0, 2.0], 'entries'),
])
def test_bad_measurements_are_refused_and_the_state_is_kept(n, bad_y, message):
    m = random_model(np.random.default_rng(3), n, 1, 1)
    kf = TimeScaleKalmanFilter(**m)
    x, P = kf.x.copy(), kf.P.copy()
    with pytest.raises(FilterError, match=message):
        kf.step(0.1, bad_y)
    with pytest.raises(FilterError, match='u'):
        kf.step(0.1, 1.0, [np.nan])
    for mu in (0.0, -1.0, np.nan, np.inf, 'a'):
        with pytest.raises(FilterError, match='mu'):
            kf.step(mu, 1.0)
    np.testing.assert_array_equal(kf.x, x)
    np.testing.assert_array_equal(kf.P, P)


@pytest.mark.parametrize('n', [1, 2, 3])
def test_an_overflowing_step_is_refused_and_nothing_non_finite_escapes(n):
    m = random_model(np.random.default_rng(4), n, 1, 0)
    m['P0'] = np.eye(n) * 1e300
    kf = TimeScaleKalmanFilter(**m)
    with np.errstate(all='ignore'), pytest.raises(FilterError, match='overflowed'):
        kf.step(1e10, None)
    np.testing.assert_array_equal(kf.P, np.eye(n) * 1e300)


@pytest.mark.parametrize('n', [1, 2, 3])
def test_non_regressive_steps_are_refused_in_every_form(n):
    A = -np.eye(n)
    kf = TimeScaleKalmanFilter(A, np.ones((1, n)), Q=np.eye(n), R=1.0, x0=np.zeros(n),
                               P0=np.eye(n))
    with pytest.raises(NonRegressiveError):
        kf.step(1.0, 0.5)           # I + A = 0
    kf.allow_nonregressive = True
    kf.step(1.0, 0.5)
    np.testing.assert_allclose(kf.P, np.eye(n), atol=1e-15)     # F = 0: P = mu Q


@pytest.mark.parametrize('n', [1, 2, 3])
@pytest.mark.parametrize('transition', ['euler', 'exact'])
def test_a_model_matrix_assigned_later_is_checked_and_used(n, transition):
    rng = np.random.default_rng(5)
    m = random_model(rng, n, 1, 1)
    kf = TimeScaleKalmanFilter(**m, transition=transition)
    kf.step(0.2, 1.0, [0.3])             # fills the transition cache for mu = 0.2
    x, P = kf.x.copy(), kf.P.copy()
    other = random_model(rng, n, 1, 1)
    for name in ('A', 'B', 'C', 'D', 'G', 'Q', 'R'):
        setattr(kf, name, other[name])
    fresh = TimeScaleKalmanFilter(**{**other, 'x0': x, 'P0': P}, transition=transition)
    a, b = kf.step(0.2, 1.0, [0.3]), fresh.step(0.2, 1.0, [0.3])
    np.testing.assert_allclose(a.P_predicted, b.P_predicted, rtol=1e-13)
    np.testing.assert_allclose(a.x_predicted, b.x_predicted, rtol=1e-13)
    with pytest.raises(FilterError, match='shape'):
        kf.A = np.eye(n + 1)
    with pytest.raises(FilterError, match='positive definite'):
        kf.R = [[-1.0]]


@pytest.mark.parametrize('n', [1, 2, 3])
def test_a_per_step_r_is_the_model_with_that_r(n):
    m = random_model(np.random.default_rng(6), n, 1, 0)
    kf = TimeScaleKalmanFilter(**m)
    ref = TimeScaleKalmanFilter(**{**m, 'R': [[0.04]]})
    a, b = kf.step(0.5, 1.0, R=0.04), ref.step(0.5, 1.0)
    np.testing.assert_array_equal(a.P_predicted, b.P_predicted)
    np.testing.assert_array_equal(kf.R, m['R'])           # the model's R is kept
    for bad in (0.0, -1.0, np.nan, [[-1.0]]):
        with pytest.raises(FilterError, match='R'):
            kf.step(0.5, 1.0, R=bad)


@pytest.mark.parametrize('n', [1, 2])
def test_the_noise_of_a_repeated_mu_follows_r_assigned_or_given(n):
    # R_d = R / mu is kept from one step to the next of the same mu: never a stale one
    rng = np.random.default_rng(7)
    m, other = random_model(rng, n, 1, 0), random_model(rng, n, 1, 0)
    kf = TimeScaleKalmanFilter(**m)
    for _ in range(3):          # the mu met once, then cached, then its R_d kept
        kf.step(1e-3, 1.0)
    for R, step_R in ((m['R'], 0.04), (other['R'], None), (other['R'], 0.5)):
        if step_R is None:
            kf.R = R
        x, P = kf.x.copy(), kf.P.copy()
        given = R if step_R is None else [[step_R]]
        fresh = TimeScaleKalmanFilter(**{**m, 'R': given, 'x0': x, 'P0': P})
        a, b = kf.step(1e-3, 1.0, R=step_R), fresh.step(1e-3, 1.0)
        np.testing.assert_array_equal(a.P_predicted, b.P_predicted)
        # and the next step with the filter's own R uses that R again
        x, P = kf.x.copy(), kf.P.copy()
        fresh = TimeScaleKalmanFilter(**{**m, 'R': kf.R, 'x0': x, 'P0': P})
        np.testing.assert_array_equal(kf.step(1e-3, 2.0).P_predicted,
                                      fresh.step(1e-3, 2.0).P_predicted)


def test_a_transition_switched_later_is_used():
    m = random_model(np.random.default_rng(7), 3, 1, 1)
    kf = TimeScaleKalmanFilter(**m)
    kf.step(0.4, 1.0, [0.2])                # caches the Euler transition for mu = 0.4
    fresh = TimeScaleKalmanFilter(**{**m, 'x0': kf.x, 'P0': kf.P}, transition='exact')
    kf.transition = 'exact'
    np.testing.assert_array_equal(kf.step(0.4, 1.0, [0.2]).P_predicted,
                                  fresh.step(0.4, 1.0, [0.2]).P_predicted)
    with pytest.raises(FilterError, match='transition'):
        kf.transition = 'rk4'


@pytest.mark.parametrize('n, p', [(1, 1), (2, 1), (3, 2), (6, 3)])
@pytest.mark.parametrize('transition', ['euler', 'exact'])
def test_a_run_equals_table_3_step_after_step(n, p, transition):
    rng = np.random.default_rng(40 + n)
    m = random_model(rng, n, p, 1)
    kf = TimeScaleKalmanFilter(**m, transition=transition)
    mus = rng.choice([0.01, 0.3, 1.0, 0.07], size=12)
    ys = rng.normal(size=(12, p)) * 3
    u = rng.normal(size=1)
    x, P = kf.x.copy(), kf.P.copy()
    res = kf.run(mus, ys, u)
    assert res.steps == 12 and res.stopped == ''
    for k in range(12):
        sampled = kf.transition_matrices(mus[k]) if transition == 'exact' else None
        x_c, P_c, x_n, P_n = table_3(m, x, P, mus[k], ys[k], u, transition, sampled)
        assert close(res.x_corrected[k], x_c, x) and close(res.P_corrected[k], P_c, P), k
        assert close(res.x_predicted[k], x_n, x) and close(res.P_predicted[k], P_n, P), k
        x, P = res.x_predicted[k], res.P_predicted[k]
    np.testing.assert_array_equal(kf.x, res.x_predicted[-1])
    np.testing.assert_array_equal(kf.P_corrected, res.P_corrected[-1])


@pytest.mark.parametrize('n, p', [(1, 1), (3, 2)])
def test_a_run_stops_before_a_refused_step_or_a_failed_test(n, p):
    rng = np.random.default_rng(9)
    m = random_model(rng, n, p, 0)
    m['A'] = -np.eye(n)                      # I + mu A singular at mu = 1
    mus = np.array([0.1, 0.2, 0.1, 1.0, 0.1])
    ys = rng.normal(size=(5, p))
    kf = TimeScaleKalmanFilter(**m)
    res = kf.run(mus, ys)
    assert (res.steps, res.stopped) == (3, 'refused')
    np.testing.assert_array_equal(kf.x, res.x_predicted[2])
    ys[1, 0] = np.nan
    res = TimeScaleKalmanFilter(**m).run(mus, ys)
    assert (res.steps, res.stopped) == (1, 'refused')
    # the test: d^2 = e^T S^-1 e of z[k] at step k's prediction, written out with numpy
    z = rng.normal(size=(3, p))
    R = np.eye(p) * 0.5
    free = TimeScaleKalmanFilter(**m).run(mus[:3], ys[[0, 2, 3]])
    d2 = []
    for k in range(3):
        x, P = free.x_predicted[k], free.P_predicted[k]
        e = z[k] - m['C'] @ x - m['D']
        d2.append(e @ np.linalg.solve(m['C'] @ P @ m['C'].T + R, e))
    z[2] += 10.0 * np.sqrt(max(d2) + 1.0)
    kf = TimeScaleKalmanFilter(**m)
    res = kf.run(mus[:3], ys[[0, 2, 3]], test=InnovationTest(z, R, max(d2[:2]) * 1.001))
    assert (res.steps, res.stopped) == (2, 'test')
    np.testing.assert_array_equal(res.x_predicted, free.x_predicted[:2])
    np.testing.assert_array_equal(kf.x, res.x_predicted[1])


@pytest.mark.parametrize('transition', ['euler', 'exact'])
def test_a_run_on_jittered_mu_is_the_step_loop_bit_for_bit(transition):
    # every mu distinct (+-5 % jitter): the run builds them all in one call, the steps one
    # at a time; both go through the same kernels, so the results are the same bits
    rng = np.random.default_rng(31)
    m = random_model(rng, 3, 2, 1)
    mus = 0.01 * (1 + rng.uniform(-0.05, 0.05, 50))
    ys = rng.normal(size=(50, 2))
    u = rng.normal(size=1)
    kf = TimeScaleKalmanFilter(**m, transition=transition)
    twin = TimeScaleKalmanFilter(**m, transition=transition)
    res = kf.run(mus, ys, u)
    for k in range(50):
        step = twin.step(float(mus[k]), ys[k], u)
        np.testing.assert_array_equal(res.x_corrected[k], step.x_corrected)
        np.testing.assert_array_equal(res.P_corrected[k], step.P_corrected)
        np.testing.assert_array_equal(res.x_predicted[k], step.x_predicted)
        np.testing.assert_array_equal(res.P_predicted[k], step.P_predicted)


@pytest.mark.parametrize('n, p', [(1, 1), (3, 2)])
def test_a_runs_innovations_are_those_of_the_steps(n, p):
    # e_k = y_k - C x_k - D and S_k = C P_k C^T + R / mu_k at each step's prior, written out
    rng = np.random.default_rng(60 + n)
    m = random_model(rng, n, p, 0)
    mus = 0.01 * (1 + rng.uniform(-0.05, 0.05, 30))
    ys = rng.normal(size=(30, p))
    kf, twin = TimeScaleKalmanFilter(**m), TimeScaleKalmanFilter(**m)
    res = kf.run(mus, ys, innovations=True)
    assert res.innovation.shape == (30, p) and res.S.shape == (30, p, p)
    for k in range(30):
        x, P = twin.x, twin.P
        e = ys[k] - m['C'] @ x - m['D']
        S = m['C'] @ P @ m['C'].T + m['R'] / mus[k]
        np.testing.assert_allclose(res.innovation[k], e, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(res.S[k], S, rtol=1e-12, atol=0.0)
        step = twin.step(float(mus[k]), ys[k])
        np.testing.assert_allclose(res.innovation[k], step.innovation, rtol=1e-14, atol=0.0)
    empty = TimeScaleKalmanFilter(**m).run(np.array([-1.0]), ys[:1], innovations=True)
    assert empty.steps == 0 and empty.innovation.shape == (0, p) and empty.S.shape == (0, p, p)


@pytest.mark.parametrize('transition', ['euler', 'exact'])
def test_a_new_mu_built_with_its_step_is_the_cached_jump_bit_for_bit(transition):
    # without an input, a step over a mu met for the first time builds the jump in the
    # same compiled call as the update and prediction; a twin whose cache already holds
    # every jump (the separate path), and the run, give the same bits
    rng = np.random.default_rng(30)
    m = random_model(rng, 3, 2, 0)
    mus = 0.01 * (1 + rng.uniform(-0.01, 0.01, 40))
    ys = rng.normal(size=(80, 2))
    kf = TimeScaleKalmanFilter(**m, transition=transition)
    twin = TimeScaleKalmanFilter(**m, transition=transition)
    for mu in mus:
        twin.transition_matrices(float(mu))          # fills the twin's cache
    # each mu twice: the second time kf caches its jump and steps with it
    twice = np.concatenate([mus, mus])
    res = TimeScaleKalmanFilter(**m, transition=transition).run(twice, ys)
    for k in range(80):
        new, cached = kf.step(float(twice[k]), ys[k]), twin.step(float(twice[k]), ys[k])
        for a, b, c in ((new.x_corrected, cached.x_corrected, res.x_corrected[k]),
                        (new.P_corrected, cached.P_corrected, res.P_corrected[k]),
                        (new.x_predicted, cached.x_predicted, res.x_predicted[k]),
                        (new.P_predicted, cached.P_predicted, res.P_predicted[k])):
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(a, c)
    assert set(kf._jumps) == set(mus.tolist())
