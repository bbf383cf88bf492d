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

"""rts_smooth and smooth_at against FilterPy, pykalman and an RTS smoother written out here."""

from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from hypothesis import assume, given, settings, strategies as st
import numpy as np
from pykalman import KalmanFilter as PyKalmanFilter
from pykalman.datasets import load_robot
import pytest
import scipy.linalg

from tskf_ros.core import FilterError, rts_smooth, smooth_at, TimeScaleKalmanFilter
from tskf_ros.core import smoother
from tskf_ros.core.timescale_kalman import NonRegressiveError

TOL = 1e-9


def close(a, b, tol=TOL):
    """Assert a == b to tol relative to the largest entry of b (at least 1)."""
    scale = max(1.0, float(np.max(np.abs(b))))
    np.testing.assert_allclose(a, b, rtol=0, atol=tol * scale)


def textbook_rts(Fs, Qs, bs, zs, Rs, H, d, x0, P0):
    """
    Kalman filter + RTS smoother on a discrete model, with explicit inverses.

    x_{k+1} = F_k x_k + b_k + w_k (Cov Q_k), z_k = H x_k + d + v_k (Cov R_k), z_k None:
    missing; x0, P0 the prior at the first point (Sarkka 2013, Theorems 4.2 and 8.2).
    """
    xf, Pf, xp, Pp = [], [], [], []
    x, P = np.array(x0, float), np.array(P0, float)
    for F, Q, b, z, R in zip(Fs, Qs, bs, zs, Rs):
        if z is not None:
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            x, P = x + K @ (z - H @ x - d), P - K @ S @ K.T
        xf.append(x)
        Pf.append(P)
        x, P = F @ x + b, F @ P @ F.T + Q
        xp.append(x)
        Pp.append(P)
    xs, Ps = list(xf), list(Pf)
    for k in range(len(zs) - 2, -1, -1):
        G = Pf[k] @ Fs[k].T @ np.linalg.inv(Pp[k])
        xs[k] = xf[k] + G @ (xs[k + 1] - xp[k])
        Ps[k] = Pf[k] + G @ (Ps[k + 1] - Pp[k]) @ G.T
    return np.array(xs), np.array(Ps), np.array(Pf)


def discrete(m, mu, kind):
    """(F, Q_d, B_d) of a jump of mu: Euler, or e^{A mu} with Q_d from a Lyapunov equation."""
    A, W, B = m['A'], m['G'] @ m['Q'] @ m['G'].T, m['B']
    if kind == 'euler':
        return np.eye(len(A)) + mu * A, mu * W, mu * B
    F = scipy.linalg.expm(A * mu)
    # d/ds e^{As} W e^{A^T s} integrated over [0, mu]: A Q_d + Q_d A^T = F W F^T - W
    Qd = scipy.linalg.solve_continuous_lyapunov(A, F @ W @ F.T - W)
    # B_d = int_0^mu e^{As} ds B = A^-1 (F - I) B (A invertible here)
    return F, Qd, np.linalg.solve(A, (F - np.eye(len(A))) @ B)


def irregular_model():
    """Return a 3-state model (A invertible, stable), 2 outputs, 1 input, 2 noises."""
    return {'A': np.array([[-0.02, 0.05, 0.0], [-0.05, -0.03, 0.01], [0.0, 0.02, -0.04]]),
            'C': np.array([[1.0, 0.0, 0.5], [0.0, 1.0, -0.3]]),
            'G': np.array([[1.0, 0.0], [0.2, 1.0], [0.0, 0.5]]),
            'Q': np.array([[0.3, 0.05], [0.05, 0.2]]),
            'R': np.array([[0.5, 0.1], [0.1, 0.4]]),
            'B': np.array([[1.0], [0.0], [0.5]]), 'D': np.array([0.3, -0.2]),
            'x0': np.array([1.0, -1.0, 0.5]), 'P0': np.diag([2.0, 1.0, 3.0])}


def irregular_data(K=40, seed=3):
    """Graininess (with 1e-3 and 30), measurements with missing rows, inputs."""
    rng = np.random.default_rng(seed)
    mu = rng.uniform(0.01, 3.0, K)
    mu[[i for i in (4, 5, 20) if i < K]] = 1e-3
    mu[[i for i in (11, 30) if i < K]] = 30.0
    y = rng.normal(size=(K, 2)) * 2
    y[[i for i in (6, 11, 12, K - 1) if i < K]] = np.nan
    return mu, y, rng.normal(size=(K, 1))


def reference(m, mu, y, u, kind):
    """textbook_rts on the discrete equivalent of the time-scale model (R_d = R / mu)."""
    jumps = [discrete(m, h, kind) for h in mu]
    zs = [None if np.isnan(row).all() else row for row in y]
    return textbook_rts([j[0] for j in jumps], [j[1] for j in jumps],
                        [j[2] @ uk for j, uk in zip(jumps, u)], zs, [m['R'] / h for h in mu],
                        m['C'], m['D'], m['x0'], m['P0'])


def assert_psd_below(Ps, Pf, tol=1e-12):
    """Assert P(t|T) <= P(t|t) in the PSD sense at every point, to tol times P(t|t)."""
    for P_s, P_f in zip(Ps, Pf):
        eig = np.linalg.eigvalsh(P_f - P_s)
        assert eig[0] >= -tol * max(1.0, float(np.max(np.abs(P_f)))), eig


@pytest.mark.parametrize('kind', ['euler', 'exact'])
def test_irregular_graininess_equals_the_textbook_smoother(kind):
    m = irregular_model()
    mu, y, u = irregular_data()
    xs, Ps = rts_smooth(m['A'], m['C'], mu, y, u=u, transition=kind,
                        **{k: m[k] for k in ('Q', 'R', 'G', 'B', 'D', 'x0', 'P0')})
    x_ref, P_ref, Pf = reference(m, mu, y, u, kind)
    assert xs.shape == (40, 3) and Ps.shape == (40, 3, 3)
    close(xs, x_ref)
    close(Ps, P_ref)
    assert_psd_below(Ps, Pf)
    # the last point: its corrected estimate (here: no measurement, the prediction)
    close(xs[-1], x_ref[-1])


def test_measurements_as_a_list_with_none_equal_nan_rows():
    m = irregular_model()
    mu, y, u = irregular_data(K=12)
    keys = ('Q', 'R', 'G', 'B', 'D', 'x0', 'P0')
    a = rts_smooth(m['A'], m['C'], mu, y, u=u, **{k: m[k] for k in keys})
    rows = [None if np.isnan(r).all() else list(r) for r in y]
    b = rts_smooth(m['A'], m['C'], list(mu), rows, u=list(u), **{k: m[k] for k in keys})
    np.testing.assert_array_equal(a.xs, b.xs)
    np.testing.assert_array_equal(a.Ps, b.Ps)


def filterpy_models():
    """Return FilterPy's test_rts.py tracker and a 2-D tracker with its white-noise Q."""
    cv = {'x': np.array([-1.0, 1.0]), 'F': np.array([[1.0, 1.0], [0.0, 1.0]]),
          'H': np.array([[1.0, 0.0]]), 'P': 0.01 * np.eye(2), 'R': np.array([[5.0]]),
          'Q': 0.001 * np.eye(2)}
    F1 = np.array([[1.0, 0.5], [0.0, 1.0]])
    q = Q_discrete_white_noise(2, dt=0.5, var=0.3)
    two_d = {'x': np.array([0.0, 1.0, 2.0, -1.0]), 'F': np.kron(np.eye(2), F1),
             'H': np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]]), 'P': np.diag([4.0, 1, 4, 1]),
             'R': np.array([[2.0, 0.3], [0.3, 1.0]]), 'Q': np.kron(np.eye(2), q)}
    return [cv, two_d]


@pytest.mark.parametrize('model', filterpy_models(), ids=['test_rts_tracker', 'tracker_2d'])
def test_mu_one_equals_filterpy_batch_filter_and_rts_smoother(model):
    rng = np.random.default_rng(7)
    p = model['H'].shape[0]
    zs = [t * np.ones(p) + rng.normal(size=p) * 4 for t in range(40)]
    zs[5] = zs[17] = None
    kf = KalmanFilter(dim_x=len(model['x']), dim_z=p)
    for key in ('x', 'F', 'H', 'P', 'R', 'Q'):
        setattr(kf, key, model[key].copy())
    mean, cov, _, _ = kf.batch_filter(zs)
    x_fp, P_fp, _, _ = kf.rts_smoother(mean, cov)
    # FilterPy's x, P are the prior before its first predict; ours are the prior at t_0,
    # after that predict: x0 = F x, P0 = F P F^T + Q.  F = I + mu A at mu = 1: A = F - I.
    F, Q = model['F'], model['Q']
    xs, Ps = rts_smooth(F - np.eye(len(F)), model['H'], np.ones(40),
                        [None if z is None else z for z in zs], Q=Q, R=model['R'],
                        x0=F @ model['x'], P0=F @ model['P'] @ F.T + Q)
    close(xs, x_fp)
    close(Ps, P_fp)
    assert_psd_below(Ps, cov)


def test_mu_one_equals_pykalman_smooth_on_the_robot_data_set():
    data = load_robot()
    K, n = data.observations.shape[0], data.transition_matrix.shape[0]
    pk = PyKalmanFilter(transition_matrices=data.transition_matrix,
                        observation_matrices=data.observation_matrix,
                        transition_covariance=data.transition_covariance,
                        observation_covariance=data.observation_covariance,
                        transition_offsets=data.transition_offsets,
                        observation_offsets=data.observation_offset,
                        initial_state_mean=data.initial_state_mean,
                        initial_state_covariance=data.initial_state_covariance)
    x_pk, P_pk = pk.smooth(data.observations)
    # pykalman x_{t+1} = A x_t + b_t + e, z_t = C x_t + d + e': at mu = 1 (Euler) that is
    # A_ts = A - I, B = I with u[t] = b_t (the offset over the jump from t; b has K - 1
    # rows, u[K-1] is not used), D = d, G = I; its initial_state_mean/covariance are the
    # prior at t_0, as our x0, P0; masked rows (the first) are missing measurements.
    u = np.vstack([data.transition_offsets, np.zeros(n)])
    xs, Ps = rts_smooth(data.transition_matrix - np.eye(n), data.observation_matrix,
                        np.ones(K), data.observations, Q=data.transition_covariance,
                        R=data.observation_covariance, B=np.eye(n), u=u,
                        D=data.observation_offset, x0=data.initial_state_mean,
                        P0=data.initial_state_covariance)
    close(xs, x_pk)
    close(Ps, P_pk)
    # and the MATLAB smoother's results stored in the data set
    close(xs, data.smoothed_state_means)
    close(Ps, data.smoothed_state_covariances)
    _, P_filt = pk.filter(data.observations)
    assert_psd_below(Ps, P_filt)


def test_no_process_noise_and_an_exact_prior_give_no_nan():
    # P(t_{k+1}|t_k) = 0: the gain is the least-squares one, x(t|T) the prior's path
    xs, Ps = rts_smooth([[0.0, 1.0], [0.0, 0.0]], [[1.0, 0.0]], [0.5, 0.5, 0.5],
                        [[1.0], [2.0], [3.0]], Q=np.zeros((2, 2)), R=1.0,
                        x0=[1.0, 2.0], P0=np.zeros((2, 2)))
    close(xs, [[1.0, 2.0], [2.0, 2.0], [3.0, 2.0]])
    close(Ps, np.zeros((3, 2, 2)))


@pytest.mark.parametrize('bad', [np.nan, np.inf])
def test_a_gain_of_a_covariance_that_is_not_finite_is_not_finite_and_raises_nothing(bad):
    """
    smoother_gain of a P(t_{k+1}|t_k) with a NaN or an infinity: a NaN gain, no exception.

    Compiled, the solve and the least squares both raise on such a matrix, and a raise
    inside the fallback was not caught (numba's internals); a sound and a singular one
    are against numpy's solve and pseudo-inverse.
    """
    P_f, F = np.diag([2.0, 1.0, 0.5]), np.eye(3) + np.diag([0.1, 0.1], 1)
    bad_P = np.eye(3)
    bad_P[0, 0] = bad
    assert np.all(np.isnan(smoother.smoother_gain(P_f, F, bad_P)))
    sound = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    close(smoother.smoother_gain(P_f, F, sound), np.linalg.solve(sound, F @ P_f).T, 1e-12)
    singular = np.diag([2.0, 1.0, 0.0])
    close(smoother.smoother_gain(P_f, F, singular), (np.linalg.pinv(singular) @ F @ P_f).T,
          1e-12)


def augmented(m, mu, y, u, kind, k, mu1):
    """textbook_rts with a point without measurement inserted at t_k + mu1 (index k + 1)."""
    jumps = [discrete(m, h, kind) for h in mu]
    jumps[k:k + 1] = [discrete(m, mu1, kind), discrete(m, mu[k] - mu1, kind)]
    us = list(u[:k + 1]) + list(u[k:])
    zs = [None if np.isnan(row).all() else row for row in y]
    zs.insert(k + 1, None)
    # y(t_k) keeps its weight R / mu_k: s adds a state, not a measurement interval
    Rs = [m['R'] / h for h in mu]
    Rs.insert(k + 1, m['R'])
    xs, Ps, _ = textbook_rts([j[0] for j in jumps], [j[1] for j in jumps],
                             [j[2] @ uk for j, uk in zip(jumps, us)], zs, Rs,
                             m['C'], m['D'], m['x0'], m['P0'])
    return xs[k + 1], Ps[k + 1]


def interpolation_cases(m, mu, y, u, kind, intervals):
    """Compare smooth_at with the brute-force augmentation at s = t_k + f mu_k."""
    t = np.concatenate(([0.0], np.cumsum(mu[:-1])))
    keys = ('Q', 'R', 'G', 'B', 'D', 'x0', 'P0')
    for k in intervals:
        for f in (1e-3, 0.37, 0.5, 0.999):
            s = t[k] + f * mu[k]
            got = smooth_at([s], m['A'], m['C'], mu, y, u=u, transition=kind,
                            **{key: m[key] for key in keys})
            x_ref, P_ref = augmented(m, mu, y, u, kind, k, s - t[k])
            close(got.xs[0], x_ref, 1e-10)
            close(got.Ps[0], P_ref, 1e-10)


def test_interpolation_equals_brute_force_augmentation_exact():
    m = irregular_model()
    mu, y, u = irregular_data(K=25)
    # after a missing measurement (6), around 1e-3 and 30 (4, 11), the last interval
    interpolation_cases(m, mu, y, u, 'exact', [0, 4, 6, 11, 17, 23])


def test_interpolation_equals_brute_force_augmentation_euler_where_jumps_compose():
    # Euler jumps compose ((I + mu2 A)(I + mu1 A) = I + mu A, and the same for Q_d, B_d)
    # when A^2 = 0, A GQG^T = 0 and A B = 0: a position-velocity pair with the noise and
    # the input on the position.  Otherwise inserting s changes the Euler model itself.
    m = {'A': np.array([[0.0, 1.0], [0.0, 0.0]]), 'C': np.array([[1.0, 0.0], [0.3, 1.0]]),
         'G': np.array([[1.0], [0.0]]), 'Q': np.array([[0.4]]), 'R': np.diag([0.5, 0.2]),
         'B': np.array([[1.0], [0.0]]), 'D': np.zeros(2), 'x0': np.array([0.0, 1.0]),
         'P0': np.eye(2)}
    mu, y, u = irregular_data(K=15, seed=5)
    interpolation_cases(m, mu, y, u, 'euler', [0, 6, 11, 13])


@pytest.mark.parametrize('kind', ['euler', 'exact'])
def test_interpolation_meets_the_points_and_returns_them_there(kind):
    m = irregular_model()
    mu, y, u = irregular_data(K=10)
    keys = ('Q', 'R', 'G', 'B', 'D', 'x0', 'P0')
    t = 2.5 + np.concatenate(([0.0], np.cumsum(mu[:-1])))
    xs, Ps = rts_smooth(m['A'], m['C'], mu, y, u=u, transition=kind,
                        **{key: m[key] for key in keys})
    eps = 1e-9 * mu[:-1]
    times = np.concatenate([t, t[:-1] + eps, t[1:] - eps])
    got = smooth_at(times, m['A'], m['C'], mu, y, t0=2.5, u=u, transition=kind,
                    **{key: m[key] for key in keys})
    np.testing.assert_array_equal(got.xs[:10], xs)
    np.testing.assert_array_equal(got.Ps[:10], Ps)
    close(got.xs[10:19], xs[:-1], 1e-6)
    close(got.xs[19:], xs[1:], 1e-6)
    close(got.Ps[19:], Ps[1:], 1e-6)
    with pytest.raises(FilterError, match="t0 must be a number, got 'a'"):
        smooth_at([0.0], m['A'], m['C'], mu, y, t0='a', **{key: m[key] for key in keys})
    with pytest.raises(FilterError, match='outside the points'):
        smooth_at([t[-1] + 0.1], m['A'], m['C'], mu, y, t0=2.5, u=u,
                  **{key: m[key] for key in keys})


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 3), p=st.integers(1, 2), seed=st.integers(0, 2**32 - 1),
       kind=st.sampled_from(['euler', 'exact']),
       mu=st.lists(st.floats(1e-3, 5.0), min_size=2, max_size=12))
def test_smoothed_covariance_is_never_above_the_filters(n, p, seed, kind, mu):
    rng = np.random.default_rng(seed)
    M, N = rng.normal(size=(n, n)), rng.normal(size=(p, p))
    model = {'A': rng.uniform(-1, 1, (n, n)), 'C': rng.normal(size=(p, n)), 'Q': M @ M.T,
             'R': N @ N.T + 0.1 * np.eye(p), 'x0': np.zeros(n), 'P0': np.eye(n),
             'transition': kind}
    y = rng.normal(size=(len(mu), p))
    y[rng.random(len(mu)) < 0.2] = np.nan
    try:
        xs, Ps = rts_smooth(mu=mu, y=y, **model)
    except NonRegressiveError:
        assume(False)
    kf = TimeScaleKalmanFilter(**model)
    steps = [kf.step(h, None if np.isnan(row).all() else row) for h, row in zip(mu, y)]
    assert np.all(np.isfinite(xs)) and np.all(np.isfinite(Ps))
    # 1e-12, or rounding where the gain's solve is ill-conditioned: an unstable A over
    # mu = 3 makes cond(P(t_{k+1}|t_k)) ~ 1e6, and even exact arithmetic on the filter's
    # float outputs then gives an eigenvalue of -1.5e-12 (seed 0, n = 3, p = 1, exact)
    cond = max(np.linalg.cond(s.P_predicted) for s in steps[:-1])
    assert_psd_below(Ps, [s.P_corrected for s in steps],
                     max(1e-12, 100 * np.finfo(float).eps * cond))


SIMPLE = {'A': [[0.0, 1.0], [-1.0, -0.2]], 'C': [[1.0, 0.0]], 'Q': np.eye(2), 'R': 1.0,
          'x0': [0.0, 0.0], 'P0': np.eye(2)}


@pytest.mark.parametrize('change, message', [
    ({'mu': [0.5, 0.0, 0.5]}, r'mu\[1\] = 0.0: every graininess must be finite and > 0'),
    ({'mu': [0.5, -1.0, 0.5]}, r'mu\[1\] = -1.0: every graininess'),
    ({'mu': [0.5, np.nan, 0.5]}, r'mu\[1\] = nan: every graininess'),
    ({'mu': [[0.5, 0.5, 0.5]]}, r'mu must be a 1-D sequence of K >= 1 graininesses'),
    ({'mu': []}, r'mu must be a 1-D sequence'),
    ({'mu': ['a', 1, 1]}, r'mu is not numeric'),
    ({'y': np.ones((2, 1))}, r'y must have shape \(3, 1\) \(one row per point\), got \(2, 1\)'),
    ({'y': np.ones((3, 2))}, r'y must have shape \(3, 1\)'),
    ({'y': [[1.0], None]}, r'y must have 3 rows \(one per point\), got 2'),
    ({'y': [[1.0], [1.0, 2.0], None]}, r'y\[1\] must have 1 entries, got 2'),
    ({'y': [[1.0], [np.inf], [1.0]]}, r'y\[1\] = \[inf\]: a row is either all NaN'),
    ({'u': np.ones((4, 1))}, r'u must have shape \(3, 1\)'),
    ({'u': [[0.0], [np.nan], [0.0]]}, r'u\[1\] = \[nan\] has non-finite entries'),
    ({'A': [[0.0, 1.0]]}, r'A must be square'),
    ({'P0': np.eye(3)}, r'P0 must have shape \(2, 2\)'),
])
def test_bad_input_is_one_clear_filter_error(change, message):
    args = {**SIMPLE, 'mu': [0.5, 0.5, 0.5], 'y': [[1.0], [2.0], [np.nan]], **change}
    for run in (rts_smooth, lambda **kw: smooth_at([0.1], **kw)):
        with pytest.raises(FilterError, match=message) as info:
            run(**args)
        assert '\n' not in str(info.value)


def test_a_bad_step_names_its_point():
    # I + mu A singular at mu = 1 (A = -I): the filter's refusal, with the point
    with pytest.raises(NonRegressiveError, match=r'^point 1 \(mu = 1.0\): I \+ mu A is'):
        rts_smooth(-np.eye(2), [[1.0, 0.0]], [0.5, 1.0, 0.5], None, Q=np.eye(2), R=1.0,
                   x0=[0.0, 0.0], P0=np.eye(2))


@pytest.mark.parametrize('kind', ['euler', 'exact'])
def test_the_compiled_forward_run_gives_the_step_loops_bits(kind):
    # jittered mu (+-5 %): rts_smooth runs the filter in one compiled run; with an input
    # column (zero, B = 0) it takes the step-by-step path; the two agree bit for bit
    rng = np.random.default_rng(31)
    K = 300
    A = np.array([[0.0, 1.0], [-2.0, -0.5]])
    mu = 0.05 * (1 + rng.uniform(-0.05, 0.05, K))
    y = rng.normal(size=(K, 1))
    kw = {'Q': np.eye(2) * 0.1, 'R': [[0.5]], 'x0': [1.0, 0.0], 'P0': np.eye(2),
          'transition': kind}
    run = rts_smooth(A, [[1.0, 0.0]], mu, y, **kw)
    loop = rts_smooth(A, [[1.0, 0.0]], mu, y, u=np.zeros((K, 1)), **kw)
    np.testing.assert_array_equal(run.xs, loop.xs)
    np.testing.assert_array_equal(run.Ps, loop.Ps)


@pytest.mark.parametrize('kind', ['euler', 'exact'])
def test_chunked_passes_are_the_textbook_smoother_and_the_whole_runs_bits(kind, monkeypatch):
    # the least chunk (16 points): the forward runs and the backward chunks split at 16,
    # 32, 48, with missing measurements across a split and at one
    m = irregular_model()
    mu, y, _ = irregular_data(K=60)
    y[15:18] = np.nan
    y[32] = np.nan
    kw = {k: m[k] for k in ('Q', 'R', 'G', 'B', 'D', 'x0', 'P0')}
    whole = rts_smooth(m['A'], m['C'], mu, y, transition=kind, **kw)
    monkeypatch.setattr(smoother, '_CHUNK_BYTES', 1)
    assert smoother._chunk(3) == 16
    xs, Ps = rts_smooth(m['A'], m['C'], mu, y, transition=kind, **kw)
    x_ref, P_ref, _ = reference(m, mu, y, np.zeros((60, 1)), kind)
    close(xs, x_ref)
    close(Ps, P_ref)
    np.testing.assert_array_equal(xs, whole.xs)
    np.testing.assert_array_equal(Ps, whole.Ps)
