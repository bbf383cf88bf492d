"""The streaming estimator session (ROS-free): equal to the offline run, and bad input."""

import numpy as np
import pytest
from tskf_ros import irregular

from tskf_ros.estimation import (ConfigError, EstimatorConfig, EstimatorSession,
                                 model_from_flat, NS)
from tskf_ros.models import LinearModel, owc, OWC_SLOPE, run_filter, spring_mass
from tskf_ros.timescale import discrete

# 1 Hz with gaps J = 3 (after 4) and J = 4 (after 12), and a dense stretch at 0.25 s
STAMPS = np.array([1, 2, 3, 4, 7, 8, 9, 10, 11, 12, 16, 16.25, 16.5, 16.75, 17, 18, 19, 20])


def measurements(model, t, seed=0):
    """Noisy measurements of a state near the model's x0 at the points t."""
    rng = np.random.default_rng(seed)
    x = model.x0 + 0.02 * rng.standard_normal((t.size, model.x0.size))
    y = x @ model.C.T + (0 if model.D is None else model.D)
    return y + np.sqrt(np.diag(model.R)) * rng.standard_normal(y.shape)


def feed(session, t, y):
    """Feed (t, y) in order; return the outcomes."""
    return [session.add(int(round(ti * NS)), yi) for ti, yi in zip(t, y)]


def collect(outcomes, kind, revised=False):
    """(stamps in s, states) of the estimates of one kind."""
    est = [e for o in outcomes for e in o.estimates if e.kind == kind and e.revised == revised]
    return np.array([e.stamp_ns / NS for e in est]), np.array([e.x for e in est]), \
        np.array([e.P for e in est])


@pytest.mark.parametrize('model, transition', [(owc(), 'euler'), (owc(), 'exact'),
                                               (spring_mass(), 'euler'),
                                               (spring_mass(), 'exact')])
def test_session_equals_offline_run(model, transition):
    # system (1) with Euler is not regressive at mu = 1 (I + A is singular): use half steps
    scale = 1.0 if model.name == 'owc' else 0.5
    stamps = STAMPS * scale
    y = measurements(model, stamps)
    session = EstimatorSession(EstimatorConfig(model, transition=transition, period=scale,
                                               nonpositive_is_gap=model.name == 'owc'))
    out = feed(session, stamps, y)
    ref = run_filter(model, discrete(stamps), y, transition=transition)
    t, x, P = collect(out, 'predicted')
    np.testing.assert_array_equal(t, stamps)
    np.testing.assert_allclose(x, ref.x_pred, rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, ref.P_pred, rtol=0, atol=1e-9)
    t, x, P = collect(out, 'corrected')
    np.testing.assert_array_equal(t, stamps[:-1])
    np.testing.assert_allclose(x, ref.x_corr[:-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(P, ref.P_corr[:-1], rtol=0, atol=1e-9)
    mus = [j.mu for o in out for j in o.jumps]
    np.testing.assert_allclose(mus, np.diff(stamps), rtol=0, atol=1e-12)
    level, _, values = session.diagnostics()
    assert values['gaps'] == 2
    assert values['gap_lengths_s'] == f'{3 * scale:g} {4 * scale:g}'
    assert values['mu_max_s'] == 4.0 * scale and values['accepted'] == stamps.size
    assert level == 'OK'


def test_non_regressive_step_is_refused_and_the_filter_goes_on():
    session = EstimatorSession(EstimatorConfig(spring_mass(), nonpositive_is_gap=False))
    session.add(1 * NS, 0.5)
    out = session.add(2 * NS, 0.5)                 # mu = 1: I + A singular (not regressive)
    assert out.reason == 'filter_error' and not out.estimates
    out = session.add(int(2.5 * NS), 0.5)          # mu = 1.5 is fine
    assert out.status == 'accepted' and [e.stamp_ns for e in out.estimates] == [
        1 * NS, int(2.5 * NS)]


def test_late_sample_is_inserted_and_rerun_equals_offline():
    model = owc()
    y = measurements(model, STAMPS)
    order = list(range(STAMPS.size))
    order.remove(8)
    order.insert(11, 8)                # t = 11 arrives after t = 16.25
    session = EstimatorSession(EstimatorConfig(model))
    out = feed(session, STAMPS[order], y[order])
    assert out[11].status == 'inserted'
    ref = run_filter(model, discrete(STAMPS), y)
    # revised estimates: from the left neighbour t = 10 up to the newest point 16.25
    t, x, _ = collect([out[11]], 'corrected', revised=True)
    np.testing.assert_array_equal(t, [10, 11, 12, 16])
    np.testing.assert_allclose(x, ref.x_corr[7:11], rtol=0, atol=1e-9)
    t, x, _ = collect([out[11]], 'predicted', revised=True)
    np.testing.assert_array_equal(t, [11, 12, 16, 16.25])
    np.testing.assert_allclose(x, ref.x_pred[8:12], rtol=0, atol=1e-9)
    # everything after the insertion equals the offline run on the full time scale
    t, x, _ = collect(out[12:], 'corrected')
    np.testing.assert_allclose(x, ref.x_corr[11:-1], rtol=0, atol=1e-9)
    # the main stream never repeats a stamp
    for kind in ('predicted', 'corrected'):
        t, _, _ = collect(out, kind)
        assert np.all(np.diff(t) > 0)
    assert session.stats.inserted == 1


def test_bad_samples_are_rejected_without_touching_the_state():
    session = EstimatorSession(EstimatorConfig(owc(), max_future=5.0))
    assert session.add(1 * NS, 200.0).status == 'accepted'
    before = session.kf.state()
    cases = [((0, 200.0), 'zero_stamp'), ((2 * NS, float('nan')), 'non_finite'),
             ((2 * NS, float('inf')), 'non_finite'), ((2 * NS, 200.0, -1.0), 'bad_variance'),
             ((2 * NS, 0.0), 'invalid_power'), ((2 * NS, -3.0), 'invalid_power'),
             ((1 * NS, 200.0), 'duplicate')]
    for args, reason in cases:
        out = session.add(*args)
        assert out.reason == reason and not out.estimates
    out = session.add(20 * NS, 200.0, now_ns=10 * NS)
    assert out.reason == 'future'
    np.testing.assert_array_equal(session.kf.state()[0], before[0])
    counts = session.stats.rejected
    assert counts['non_finite'] == 2 and counts['invalid_power'] == 2 and counts['future'] == 1


def test_too_old_and_clock_jumps():
    cfg = EstimatorConfig(owc(), history_window=5.0, max_backward=20.0, max_jump=30.0)
    session = EstimatorSession(cfg)
    feed(session, np.arange(1.0, 13.0), np.full(12, 200.0))
    assert session.add(3 * NS, 200.0).reason == 'too_old'           # 9 s late > 5 s
    out = session.add(100 * NS, 200.0)                               # 88 s ahead
    assert out.status == 'reset' and out.reason == 'forward_jump'
    assert [e.kind for e in out.estimates] == ['predicted']
    np.testing.assert_array_equal(out.estimates[0].x, owc().x0)
    out = session.add(50 * NS, 200.0)                                # 50 s back
    assert out.status == 'reset' and out.reason == 'backward_jump'
    assert session.stats.resets['forward_jump'] == 1
    assert session.stats.resets['backward_jump'] == 1


def test_long_gap_warns():
    session = EstimatorSession(EstimatorConfig(owc(), max_gap=5.0))
    feed(session, np.array([1.0, 2.0, 9.0, 10.0]), np.full(4, 200.0))
    level, message, values = session.diagnostics()
    assert level == 'WARN' and 'max_gap' in message and values['gap_max_s'] == 7.0
    assert session.diagnostics()[0] == 'OK'


def test_outputs_stay_finite_and_psd_under_hostile_input():
    rng = np.random.default_rng(5)
    session = EstimatorSession(EstimatorConfig(spring_mass(), max_jump=1e4, max_backward=1e4,
                                               history_window=1e4, nonpositive_is_gap=False))
    stamps = np.cumsum(rng.exponential(1.0, 400)) + 1
    stamps[rng.integers(0, 400, 40)] *= rng.uniform(0.5, 1.5, 40)
    values = rng.normal(0, 1e6, 400)
    values[rng.integers(0, 400, 20)] = np.nan
    for t, v in zip(stamps, values):
        for e in session.add(int(t * NS), v).estimates:
            assert np.all(np.isfinite(e.x)) and np.all(np.isfinite(e.P))
            np.testing.assert_array_equal(e.P, e.P.T)
            assert np.linalg.eigvalsh(e.P)[0] >= -1e-9 * max(1.0, np.abs(e.P).max())


def test_model_from_flat_and_bad_configs():
    m = model_from_flat(A=[0, 1, -1, -2], C=[1, 0], G=[0, 1], Q=[1], R=[2], x0=[1, 1],
                        P0=[2, 0, 0, 3])
    np.testing.assert_array_equal(m.A, spring_mass().A)
    assert m.G.shape == (2, 1) and m.D is None
    with pytest.raises(ConfigError, match='A must have n'):
        model_from_flat(A=[1, 2], C=[1], Q=[1], R=[1], x0=[0], P0=[1])
    with pytest.raises(ConfigError, match='Q must have'):
        model_from_flat(A=[1], C=[1], Q=[1, 0], R=[1], x0=[0], P0=[1])
    with pytest.raises(ConfigError, match='indefinite'):
        EstimatorConfig(model_from_flat(A=[1], C=[1], Q=[-1], R=[1], x0=[0], P0=[1]))
    with pytest.raises(ConfigError, match='period'):
        EstimatorConfig(owc(), period=-1.0)
    with pytest.raises(ConfigError, match='transition'):
        EstimatorConfig(owc(), transition='rk4')


def test_reconfigure_keeps_the_estimate():
    session = EstimatorSession(EstimatorConfig(owc()))
    feed(session, np.arange(1.0, 5.0), np.full(4, 200.0))
    x = session.kf.x.copy()
    session.reconfigure(EstimatorConfig(owc(), transition='exact'))
    np.testing.assert_array_equal(session.kf.x, x)
    assert session.kf.transition == 'exact'
    out = session.reconfigure(EstimatorConfig(spring_mass()))
    assert out.status == 'reset' and session.pending() is None


def test_sampling_intervals_are_checked_against_fang_section_iii():
    # a scalar unstable model: no pathological interval; Theorem 2 bounds for 1..4 periods
    cfg = EstimatorConfig(model=owc(), max_gap=100.0)
    s = EstimatorSession(cfg)
    t = 10 * NS
    for dt in (1, 1, 3, 1, 4, 2):
        t += dt * NS
        s.add(t, 200.0)
    level, _, values = s.diagnostics()
    assert values['intervals_seen_periods'] == '1 2 3 4'
    assert values['interval_warnings'] == ''
    F, Qd, _ = s.kf.transition_matrices(1.0)
    lo, hi = irregular.scalar_peak_bounds(F[0, 0], OWC_SLOPE, Qd[0, 0], 100.0, 1, 4)
    assert values['theorem2_peak_bound_low'] == pytest.approx(lo)
    assert values['theorem2_peak_bound_high'] == pytest.approx(hi)
    # eigenvalues +-2 of the one-period transition: every even interval is pathological
    # (I + h A = diag(2, -2) with h = 1), and C = [1, 1] cannot tell the modes apart
    model = LinearModel('pm2', A=np.diag([1.0, -3.0]), C=np.array([[1.0, 1.0]]),
                        Q=np.eye(2), R=np.eye(1), x0=np.zeros(2), P0=np.eye(2))
    s = EstimatorSession(EstimatorConfig(model=model, nonpositive_is_gap=False))
    t = 10 * NS
    for dt in (1, 1, 2, 1):
        t += dt * NS
        s.add(t, 0.5)
    level, message, values = s.diagnostics()
    assert level == 'WARN' and 'interval(s) 2' in message
    assert values['interval_warnings'].startswith('2: degenerate')
