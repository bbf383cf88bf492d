"""tskf_ros.core.kalman's predict and update against FilterPy's KalmanFilter, to 1e-12."""

from filterpy.kalman import KalmanFilter
import numpy as np
import pytest

from tskf_ros.core import kalman

RTOL = 1e-12
SIZES = [(n, p) for n in (1, 2, 5) for p in (1, 2)]


def spd(rng, k, floor):
    """Return a random symmetric positive definite k x k matrix (eigenvalues >= floor)."""
    M = rng.normal(size=(k, k))
    return M @ M.T + floor * np.eye(k)


def random_model(rng, n, p, m=2):
    """Return x, P, F, Q, B, u, z, H, R, d of a random model with n states, p outputs."""
    return {'x': rng.normal(size=n), 'P': spd(rng, n, 0.5), 'F': rng.normal(size=(n, n)),
            'Q': spd(rng, n, 0.1), 'B': rng.normal(size=(n, m)), 'u': rng.normal(size=m),
            'z': rng.normal(size=p) * 3, 'H': rng.normal(size=(p, n)), 'R': spd(rng, p, 0.5),
            'd': rng.normal(size=p)}


def filterpy_filter(m):
    """Return FilterPy's KalmanFilter set to the model m (1-D state, as tskf_ros keeps it)."""
    n, p = m['H'].shape[1], m['H'].shape[0]
    kf = KalmanFilter(dim_x=n, dim_z=p, dim_u=m['B'].shape[1])
    kf.x, kf.P = m['x'].copy(), m['P'].copy()
    kf.F, kf.Q, kf.B = m['F'], m['Q'], m['B']
    kf.H, kf.R = m['H'], m['R']
    return kf


def assert_close(got, want):
    """Assert |got - want| <= RTOL (|want| + max |want|) entrywise."""
    want = np.asarray(want, dtype=float)
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=RTOL * np.max(np.abs(want)))


@pytest.mark.parametrize('n, p', SIZES)
def test_predict_is_filterpys_predict(n, p):
    rng = np.random.default_rng(100 * n + p)
    for _ in range(5):
        m = random_model(rng, n, p)
        ref = filterpy_filter(m)
        ref.predict(u=m['u'])
        # x = F x + B u, P = F P F^T + Q
        x, P = kalman.predict(m['x'], m['P'], m['F'], m['Q'], m['B'] @ m['u'])
        assert_close(x, ref.x)
        assert_close(P, ref.P)
        np.testing.assert_array_equal(P, P.T)


@pytest.mark.parametrize('n, p', SIZES)
def test_update_is_filterpys_update_in_joseph_form(n, p):
    rng = np.random.default_rng(200 + 10 * n + p)
    for k in range(5):
        m = random_model(rng, n, p)
        d = m['d'] if k % 2 else np.zeros(p)
        ref = filterpy_filter(m)
        # FilterPy has no offset d: its y = z - H x with z - d is tskf_ros's z - (H x + d)
        ref.update(m['z'] - d)
        x, P, y, S, K = kalman.update(m['x'], m['P'], m['z'], m['H'], m['R'], d)
        for got, want in ((x, ref.x), (P, ref.P), (y, ref.y), (S, ref.S), (K, ref.K)):
            assert_close(got, want)
        np.testing.assert_array_equal(P, P.T)


@pytest.mark.parametrize('n, p', SIZES)
def test_update_batch_is_update_run_by_run(n, p):
    rng = np.random.default_rng(300 + 10 * n + p)
    runs = [random_model(rng, n, p) for _ in range(6)]
    stack = {key: np.stack([m[key] for m in runs]) for key in ('x', 'P', 'z', 'H', 'R', 'd')}
    x, P = kalman.update_batch(stack['x'], stack['P'], stack['z'], stack['H'], stack['R'],
                               stack['d'])
    assert x.shape == (6, n) and P.shape == (6, n, n)
    for i, m in enumerate(runs):
        x_i, P_i, _, _, _ = kalman.update(m['x'], m['P'], m['z'], m['H'], m['R'], m['d'])
        np.testing.assert_array_equal(x[i], x_i)
        np.testing.assert_array_equal(P[i], P_i)
