"""
TimeScaleKalmanFilter.step at every size against Table 3 written out here in plain numpy.

The filter computes the step in three forms (plain floats for n = 1 and for n = 2 with one
output, numpy with an O(n^2 p) Joseph form and F P(t|t) F^T + Q_d above); each must give
what Bohner & Wintz Table 3 gives term by term, with the corrected estimate of the
discrete filter (R_d = R / mu, Joseph form), to 1e-12 relative.  Relative to what:
the norm of the quantity plus the norm of the prior it is computed from (x or P), since a
corrected covariance much smaller than the prior carries the rounding of the prior.
Random models at n = 1, 2, 3, 6, 20, 50, every p = 1..n, with and without an input,
Euler and exact transitions, and gaps (y = None).
"""

import numpy as np
import pytest
import scipy.linalg

from tskf_ros.core.timescale_kalman import (FilterError, NonRegressiveError,
                                            TimeScaleKalmanFilter)

RTOL = 1e-12
SIZES = (1, 2, 3, 6, 20, 50)


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
