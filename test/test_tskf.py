"""TimeScaleKalmanFilter against formulations written independently here."""

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from tskf_ros.core.matrices import FilterError, is_invertible, is_psd
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.core.transitions import van_loan


def random_model(rng, n=3, p=2, r=2):
    """Draw a random stable-ish model with SPD covariances."""
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
    m = random_model(rng)
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
    m = random_model(rng)
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


def test_exact_transition_van_loan_matches_quadrature():
    A = np.array([[0.0, 1.0], [-1.0, -2.0]])
    GQGt = np.array([[0.0, 0.0], [0.0, 1.0]])
    mu = 1.7
    F, Qd = van_loan(A, GQGt, mu)
    np.testing.assert_allclose(F, scipy.linalg.expm(A * mu), atol=1e-12)
    ref, _ = scipy.integrate.quad_vec(
        lambda s: scipy.linalg.expm(A * s) @ GQGt @ scipy.linalg.expm(A * s).T, 0, mu,
        epsabs=1e-13)
    np.testing.assert_allclose(Qd, ref, atol=1e-10)


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
