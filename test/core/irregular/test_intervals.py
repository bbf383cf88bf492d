"""Fang & de Callafon (2011): switching and lifted filters, interval checks, Theorem 2, drogue."""

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from tskf_ros.core import irregular as ir
from tskf_ros.core import linear_models as models
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.experiments import drogue, jump_covariance as jc_experiment


def rotation(angle: float, scale: float = 1.0) -> np.ndarray:
    """Return scale * [[cos, -sin], [sin, cos]]: eigenvalues scale * exp(+-j angle)."""
    c, s = np.cos(angle), np.sin(angle)
    return scale * np.array([[c, -s], [s, c]])


ROT3 = rotation(2 * np.pi / 3, 1.1)


# ---------------------------------------------------------------------------------------
# Definitions 2 and 3 on hand-checkable cases
# ---------------------------------------------------------------------------------------

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


def pbh_detectable(Ak: np.ndarray, C: np.ndarray, tol: float = 1e-9) -> bool:
    """PBH on A^k itself: rank [A^k - lambda I; C] = n for every |lambda| >= 1."""
    n = Ak.shape[0]
    for lam in np.linalg.eigvals(Ak):
        if abs(lam) < 1 - 1e-9:
            continue
        M = np.vstack([Ak - lam * np.eye(n), C]) / max(1.0, abs(lam))
        if np.linalg.svd(M, compute_uv=False)[-1] <= tol:
            return False
    return True


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


# ---------------------------------------------------------------------------------------
# Switching filter (13)-(17) == lifted filter (3)-(8) at the sampling instants
# ---------------------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------------------
# Theorem 2
# ---------------------------------------------------------------------------------------

def peak_map(a, c, q, r, kappa, X):
    """f^kappa(g(X)) written here: g in information form (1/X + c^2/r)^-1, f(Y) = a^2 Y + q."""
    Y = 1.0 / (1.0 / X + c * c / r)
    for _ in range(kappa):
        Y = a * a * Y + q
    return Y


def test_scalar_fixed_points_hand_numbers():
    # a = 1.2, c = q = r = 1, k = 1: X^2 - 1.44 X - 1 = 0
    lo, hi = ir.scalar_peak_bounds(1.2, 1.0, 1.0, 1.0, 1, 4)
    assert lo == pytest.approx((1.44 + np.sqrt(1.44 ** 2 + 4)) / 2, rel=1e-12)
    assert hi == pytest.approx(peak_map(1.2, 1.0, 1.0, 1.0, 4, hi), rel=1e-12)
    # the module's map (eq. (22)-(23) as printed) agrees with the information form
    for X in (0.1, 1.0, 17.0):
        assert ir.scalar_peak_map(1.2, 1.0, 1.0, 1.0, 3, X) == pytest.approx(
            peak_map(1.2, 1.0, 1.0, 1.0, 3, X), rel=1e-12)
    assert hi == pytest.approx(11.454149197572, rel=1e-10)
    # a = 1: q_k = k q; X^2 - 2 X - 2 = 0 for k = 2
    assert ir.scalar_fixed_point(1.0, 1.0, 1.0, 1.0, 2) == pytest.approx(1 + np.sqrt(3))
    with pytest.raises(ir.IrregularError):
        ir.scalar_fixed_point(1.5, 0.0, 1.0, 1.0, 2)


# README's table (bounds and the peaks seen on 5 sequences of 30 intervals, seed 7), to the
# printed digits: (a, c, q, r, tau, eta), (bounds), (peaks seen), half a printed unit
@pytest.mark.parametrize('a, c, q, r, tau, eta, bounds, seen, tol', [
    (1.3, 1.0, 1.0, 2.0, 1, 5, (3.038, 44.927), (3.103, 44.925), 5e-4),
    (1.0, 0.7, 0.5, 1.0, 2, 6, (2.014, 4.394), (2.035, 4.392), 5e-4),
    (-1.1, 2.0, 0.3, 0.5, 1, 3, (0.4163, 1.3043), (0.4163, 1.3043), 5e-5),
    (0.8, 1.0, 1.0, 1.0, 1, 4, (1.370, 2.431), (1.371, 2.431), 5e-4),   # stable a
])
def test_peak_covariances_stay_within_theorem2_bounds(a, c, q, r, tau, eta, bounds, seen, tol):
    rng = np.random.default_rng(7)
    lo, hi = ir.scalar_peak_bounds(a, c, q, r, tau, eta)
    # fixed points of the map written in this file
    assert peak_map(a, c, q, r, tau, lo) == pytest.approx(lo, rel=1e-11)
    assert peak_map(a, c, q, r, eta, hi) == pytest.approx(hi, rel=1e-11)
    assert (lo, hi) == pytest.approx(bounds, abs=tol * 1.01)
    all_peaks = []
    for _ in range(5):
        gaps = rng.integers(tau, eta + 1, size=30)
        times = np.concatenate([[0], np.cumsum(gaps)])
        y = np.full((times[-1] + 1, 1), np.nan)
        y[times, 0] = 0.0
        P0 = rng.uniform(lo, hi)
        sw = ir.run_switching([[a]], [[c]], Q=[[q]], R=[[r]], x0=[0.0], P0=[[P0]], y=y)
        peaks = sw.P_prior[times, 0, 0]
        all_peaks.extend(peaks)
        assert np.all(peaks >= lo * (1 - 1e-12)) and np.all(peaks <= hi * (1 + 1e-12))
        # eq. (24): sandwiched by the single-rate sequences from ordered starts
        p_tau, p_eta = 0.5 * P0, 2 * P0
        for k, peak in zip(gaps, peaks[1:]):
            p_tau = peak_map(a, c, q, r, tau, p_tau)
            p_eta = peak_map(a, c, q, r, eta, p_eta)
            assert p_tau <= peak * (1 + 1e-12) and peak <= p_eta * (1 + 1e-12)
    assert (min(all_peaks), max(all_peaks)) == pytest.approx(seen, abs=tol * 1.01)


# ---------------------------------------------------------------------------------------
# The time-scale filter around one jump (not in the papers)
# ---------------------------------------------------------------------------------------

def test_jump_covariance_matches_the_time_scale_filter_itself():
    for model, transition, J in ((models.owc(), 'euler', 3.0), (models.owc(), 'exact', 2.0),
                                 (models.spring_mass(), 'exact', 4.0),
                                 (models.spring_mass(), 'euler', 2.5)):
        r = ir.jump_covariance(model, J, transition=transition)
        kf = TimeScaleKalmanFilter(model.A, model.C, Q=model.Q, R=model.R, G=model.G,
                                   D=model.D, x0=model.x0, P0=r.P_steady,
                                   transition=transition, allow_nonregressive=True)
        y = model.C @ model.x0 + (0 if model.D is None else model.D)
        for _ in range(3):
            kf.step(1.0, y)
        np.testing.assert_allclose(kf.P, r.P_steady, rtol=1e-9)
        kf.step(J, y)
        np.testing.assert_allclose(kf.P, r.P_peak, rtol=1e-9)
        kf.step(1.0, y)
        np.testing.assert_allclose(kf.P_corrected, r.P_after, rtol=1e-9)


def test_jump_covariance_owc_numbers():
    m = models.owc()
    c2, R = models.OWC_SLOPE ** 2, 100.0
    # Euler, h = 1: F = 2, Q_d = 1; P_ss solves P = 4 P (R/h) / (c^2 P + R/h) + 1
    P_ss = ir.steady_covariance(m, 1.0)[0, 0]
    assert P_ss == pytest.approx(4 * P_ss * R / (c2 * P_ss + R) + 1, rel=1e-12)
    for J in (1.0, 2.0, 6.0):
        r = ir.jump_covariance(m, J)
        # P_peak = (1 + J)^2 P_c + J with P_c corrected by R / J
        P_c = P_ss * (R / J) / (c2 * P_ss + R / J)
        assert r.P_peak[0, 0] == pytest.approx((1 + J) ** 2 * P_c + J, rel=1e-12)
    assert ir.jump_covariance(m, 1.0).P_peak[0, 0] == pytest.approx(P_ss, rel=1e-12)
    table = jc_experiment.table(m)
    peaks = [row['peak_variances'][0] for row in table['exact']]
    assert np.all(np.diff(peaks) > 0) and peaks[-1] == pytest.approx(81383.57, rel=1e-5)
    # a jump that recurs every 5 points: the periodic peak is at least the single one
    once = ir.jump_covariance(m, 4.0, transition='exact')
    periodic = ir.jump_covariance(m, 4.0, transition='exact', every=5)
    assert periodic.P_peak[0, 0] >= once.P_peak[0, 0] * (1 - 1e-12)


def scalar_dare(F, Qd, c2, Rd):
    """Predicted steady variance of a scalar KF: P = F^2 P Rd / (c^2 P + Rd) + Qd (closed form)."""
    # c^2 P^2 + (Rd (1 - F^2) - Qd c^2) P - Qd Rd = 0, positive root
    b = Rd * (1 - F * F) - Qd * c2
    return (-b + np.sqrt(b * b + 4 * c2 * Qd * Rd)) / (2 * c2)


def test_jump_covariance_readme_numbers_owc():
    # README: peak variance of theta 1.001 ... 6.002 rad^2 (I + mu A) and 3.2, 26.8, 201,
    # 1490, 11014, 81384 (exact) for J = 1..6; corrected 2.46e-4 whatever J
    m = models.owc()
    c2, R = models.OWC_SLOPE ** 2, 100.0
    euler = [1.001, 2.001, 3.001, 4.002, 5.002, 6.002]
    exact = [(3.2, 0.05), (26.8, 0.05), (201, 0.5), (1490, 0.5), (11014, 0.5), (81384, 0.5)]
    # exact sampled plant x' = x + w: F = e^h, Q_d = (e^{2h} - 1) / 2 (closed form)
    P_ss_exact = scalar_dare(np.e, (np.e ** 2 - 1) / 2, c2, R)
    for J, want_euler, (want_exact, tol) in zip(range(1, 7), euler, exact):
        r_eu = ir.jump_covariance(m, float(J))
        r_ex = ir.jump_covariance(m, float(J), transition='exact')
        assert r_eu.P_peak[0, 0] == pytest.approx(want_euler, abs=5e-4)
        assert r_ex.P_peak[0, 0] == pytest.approx(want_exact, abs=tol)
        P_c = P_ss_exact * (R / J) / (c2 * P_ss_exact + R / J)
        assert r_ex.P_peak[0, 0] == pytest.approx(
            np.exp(2 * J) * P_c + (np.exp(2 * J) - 1) / 2, rel=1e-9)
        for r in (r_eu, r_ex):
            assert r.P_after[0, 0] == pytest.approx(2.46e-4, abs=5e-7)
            # one measurement with R / h = 100 on the peak: P_peak R / (c^2 P_peak + R)
            assert r.P_after[0, 0] == pytest.approx(
                r.P_peak[0, 0] * R / (c2 * r.P_peak[0, 0] + R), rel=1e-9)


def test_jump_covariance_readme_numbers_spring_mass():
    # README: position variance 4.5, 10.6, 19, 29.6, 42.3 for J = 2..6 with I + mu A; with
    # the exact transition it stays near 0.25.  Reference: scipy's DARE at h = 1, then the
    # correction with R / J and the prediction over J written here.
    m = models.spring_mass()
    A, C, GQG, R = m.A, m.C, m.G @ m.Q @ m.G.T, m.R
    P_ss = scipy.linalg.solve_discrete_are((np.eye(2) + A).T, C.T, GQG, R)
    for J, want in zip(range(2, 7), [4.5, 10.6, 19.0, 29.6, 42.3]):
        r = ir.jump_covariance(m, float(J))
        assert r.P_peak[0, 0] == pytest.approx(want, abs=0.05)
        Rd = R / J
        L = P_ss @ C.T @ np.linalg.inv(C @ P_ss @ C.T + Rd)
        P_c = P_ss - L @ C @ P_ss
        F = np.eye(2) + J * A
        np.testing.assert_allclose(r.P_peak, F @ P_c @ F.T + J * GQG, rtol=1e-8, atol=1e-10)
        ex = ir.jump_covariance(m, float(J), transition='exact')
        assert 0.24 <= ex.P_peak[0, 0] <= 0.25


def test_jump_covariance_flags_the_nonregressive_spring_mass_step():
    m = models.spring_mass()
    assert not ir.jump_covariance(m, 1.0).regressive    # I + A is singular (Cai's mu = 1)
    assert ir.jump_covariance(m, 2.0).regressive
    r6 = ir.jump_covariance(m, 6.0)
    np.testing.assert_allclose(np.diag(r6.P_peak), [42.25, 133.25], rtol=1e-9)


# ---------------------------------------------------------------------------------------
# The drogue (Section IV)
# ---------------------------------------------------------------------------------------

def test_drogue_rms_velocity_error():
    r = drogue.run(drogue.DrogueConfig(seed=6))
    rms = r.rms()
    # README, seed 6: drogue velocity 0.0094 m/s (filter sigma 0.0088), flow 0.0095 m/s,
    # 0.0121 m/s without the inverse of eq. (27); to the printed digit
    assert rms['drogue_velocity'] == pytest.approx(0.0094, abs=5e-5)
    assert rms['filter_velocity_sd'] == pytest.approx(0.0088, abs=5e-5)
    assert rms['flow_velocity'] == pytest.approx(0.0095, abs=5e-5)
    assert rms['flow_velocity_without_inverse_27'] == pytest.approx(0.0121, abs=5e-5)
    assert rms['drogue_velocity'] < 0.015
    assert 0.4 < rms['drogue_velocity'] / rms['filter_velocity_sd'] < 1.6
    # the inverse of eq. (27) adds the slip the drogue velocity alone misses
    assert rms['flow_velocity'] < rms['flow_velocity_without_inverse_27']
    assert rms['flow_velocity'] < 0.015
    m = drogue.model_matrices(r.cfg)
    T = r.intervals()
    assert T[0] == 1 and T[-1] > 90
    assert ir.theorem1(m['A'], m['C'], T).stable


@pytest.mark.slow
def test_drogue_rms_over_seeds_1_to_20():
    # README: over seeds 1-20 the RMS error after the first dive ranges over 0.0047-0.0115
    v = [drogue.run(drogue.DrogueConfig(seed=seed)).rms()['drogue_velocity']
         for seed in range(1, 21)]
    assert min(v) == pytest.approx(0.0047, abs=5e-5)
    assert max(v) == pytest.approx(0.0115, abs=5e-5)


def test_drogue_main_writes_figure_and_summary(tmp_path, capsys):
    assert drogue.main(['--out', str(tmp_path), '--hours', '1.5']) == 0
    assert (tmp_path / 'drogue.png').stat().st_size > 10_000
    data = json.loads((tmp_path / 'drogue.json').read_text())
    # 1.5 h, seed 6: the numbers of the run itself, and Theorem 1 on its intervals
    rms = data['rms']
    assert rms['drogue_velocity'] == pytest.approx(0.007914, abs=5e-6)
    assert rms['flow_velocity'] == pytest.approx(0.008061, abs=5e-6)
    assert rms['flow_velocity_without_inverse_27'] == pytest.approx(0.011924, abs=5e-6)
    assert data['pathological_intervals'] == [] and data['degenerate_intervals'] == []
    assert data['theorem1_stable'] is True
    out = capsys.readouterr().out
    assert f"drogue {rms['drogue_velocity']:.5f} m/s" in out and 'stable: True' in out


def test_drogue_estimator_yaml_is_the_drogue_model():
    yaml = pytest.importorskip('yaml')
    path = Path(__file__).resolve().parent.parent / 'config' / 'drogue_estimator.yaml'
    p = yaml.safe_load(path.read_text())['/**/timescale_estimator']['ros__parameters']
    kf = TimeScaleKalmanFilter(np.reshape(p['A'], (2, 2)), [p['C']], Q=[p['Q']], R=[p['R']],
                               G=p['G'], B=p['B'], x0=p['x0'], P0=np.reshape(p['P0'], (2, 2)),
                               transition=p['transition'])
    m = drogue.model_matrices(drogue.DrogueConfig())
    F, Qd, Bd = kf.transition_matrices(p['period'])
    np.testing.assert_allclose(F, m['A'], atol=1e-12)
    np.testing.assert_allclose(Bd, m['B'], atol=1e-12)
    # same velocity variance per step; R / mu is the 3 m fix at mu = period
    assert Qd[1, 1] == pytest.approx(m['Q'][1, 1], rel=1e-9)
    assert p['R'][0] / p['period'] == pytest.approx(m['R'][0, 0])
