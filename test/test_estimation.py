"""The streaming estimator session (ROS-free): equal to the offline run, and bad input."""

import numpy as np
import pytest

from tskf_ros.core.linear_models import LinearModel, owc, OWC_SLOPE, run_filter, spring_mass
from tskf_ros.core.time_scales import discrete
from tskf_ros.owc.estimator_session import (ConfigError, EstimatorConfig, EstimatorSession,
                                            model_from_flat, NS)

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


def fang_scalar_fixed_point(a, c, q, r, kappa, iterations=20_000):
    """
    Theorem 2's fixed point of X = f^kappa(g(X)) by plain iteration from X = q.

    Written here independently of tskf_ros.core.irregular (which solves a quadratic):
    g(X) = (1/X + c^2/r)^-1 (information form of eq. (23)), f(Y) = a^2 Y + q (eq. (22)).
    """
    X = q
    for _ in range(iterations):
        Y = 1.0 / (1.0 / X + c * c / r)
        for _ in range(kappa):
            Y = a * a * Y + q
        if abs(Y - X) <= 1e-15 * X:
            break
        X = Y
    return Y


@pytest.mark.parametrize('period', [1.0, 0.5, 2.0])
def test_sampling_intervals_are_checked_against_fang_section_iii(period):
    # a scalar unstable model: no pathological interval; Theorem 2 bounds for 1..4 periods
    cfg = EstimatorConfig(model=owc(), max_gap=100.0, period=period)
    s = EstimatorSession(cfg)
    t = 10 * NS
    for dt in (1, 1, 3, 1, 4, 2):
        t += int(round(dt * period * NS))
        s.add(t, 200.0)
    level, _, values = s.diagnostics()
    assert values['intervals_seen_periods'] == '1 2 3 4'
    assert values['interval_warnings'] == ''
    # Fang's discrete system of one nominal period h (Euler: a = 1 + h, q = h G Q G^T = h)
    # measured with R / h at every sample (Table 3's R_d at mu = h): Theorem 2 for 1 and 4
    a, q, r = 1.0 + period, period, 100.0 / period
    lo = fang_scalar_fixed_point(a, OWC_SLOPE, q, r, 1)
    hi = fang_scalar_fixed_point(a, OWC_SLOPE, q, r, 4)
    assert values['theorem2_peak_bound_low'] == pytest.approx(lo, rel=1e-9)
    assert values['theorem2_peak_bound_high'] == pytest.approx(hi, rel=1e-9)
    if period == 1.0:
        # a = 2, q = 1, r = 100, kappa = 1: X = 4 r X / (c^2 X + r) + 1, that is
        # c^2 X^2 - (3 r + c^2) X - r = 0
        c2 = OWC_SLOPE ** 2
        b = 300 + c2
        assert lo == pytest.approx((b + np.sqrt(b * b + 400 * c2)) / (2 * c2), rel=1e-12)
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


# -- the input u (add_input): zero-order hold, input-only points ---------------------------

def double_integrator(**extra):
    """Return the drogue's model: x = [d, d'], u = d'' (drogue_estimator.yaml, smaller R)."""
    return model_from_flat(A=[0, 1, 0, 0], B=[0, 1], C=[1, 0], G=[0, 1], Q=[1e-3], R=[0.5],
                           x0=[0, 0], P0=[1, 0, 0, 1], name='drogue', **extra)


def direct_run(model, transition, points):
    """
    Run the core filter over (stamp s, y or None, u in force) points; return its outputs.

    Returns ({stamp: predicted x, P} at every point but the first, {stamp: corrected x, P}
    at the points with a measurement but the last).
    """
    kf = model.make_filter(transition)
    pred, corr = {}, {}
    for (t, y, u), (t_next, _, _) in zip(points, points[1:]):
        res = kf.step(t_next - t, y, u)
        pred[t_next] = (res.x_predicted, res.P_predicted)
        if y is not None:
            corr[t] = (res.x_corrected, res.P_corrected)
    return pred, corr


def by_stamp(outcomes, kind, revised=False):
    """Return {stamp s: (x, P)} of one kind of estimate, checking no stamp repeats."""
    est = [e for o in outcomes for e in o.estimates if e.kind == kind and e.revised == revised]
    stamps = [e.stamp_ns / NS for e in est]
    assert len(set(stamps)) == len(stamps), stamps
    return {e.stamp_ns / NS: (e.x, e.P) for e in est}


def assert_same(got, want):
    assert sorted(got) == sorted(want)
    for t in want:
        np.testing.assert_allclose(got[t][0], want[t][0], rtol=0, atol=1e-9, err_msg=str(t))
        np.testing.assert_allclose(got[t][1], want[t][1], rtol=0, atol=1e-9, err_msg=str(t))


@pytest.mark.parametrize('transition', ['exact', 'euler'])
def test_inputs_are_held_over_a_gap_like_input_only_points(transition):
    model = double_integrator()
    # y is random, unrelated to the model's prediction: no innovation gate (gate=0)
    session = EstimatorSession(EstimatorConfig(model, transition=transition, gate=0.0,
                                               nonpositive_is_gap=False, max_gap=100.0))
    rng = np.random.default_rng(3)
    # (stamp, 'y' or 'u'), in arrival order: an input before the first measurement is held;
    # the input at 2 arrives before its measurement, the one at 21 after it (both merge);
    # the gap 3 -> 20 holds the inputs at 2.5, 5, ..., 17.5 piece by piece
    inputs = [0.5, 2.0, 2.5] + list(np.arange(5.0, 20.0, 2.5)) + [21.0]
    measured = [1.0, 2.0, 3.0, 20.0, 21.0, 22.0]
    events = sorted([(t, 'u') for t in inputs] + [(t, 'y') for t in measured],
                    key=lambda e: (e[0], e[1] == ('y' if e[0] == 2.0 else 'u')))
    u = {t: rng.standard_normal(1) for t in inputs}
    y = {t: rng.standard_normal(1) for t in measured}
    out = [session.add_input(int(t * NS), u[t]) if kind == 'u' else session.add(int(t * NS),
                                                                                y[t])
           for t, kind in events]
    assert [o.reason for o in out[:2]] == ['held', ''] and out[3].reason == 'merged'
    assert [o.reason for o in out if o.reason] == ['held', 'merged', 'merged']
    assert all(o.status == 'accepted' for o in out)
    # the direct run: every stamp a point, the input in force held from its stamp
    points, in_force = [], u[0.5]
    for t in sorted(set(inputs + measured) - {0.5}):
        in_force = u.get(t, in_force)
        points.append((t, y.get(t), in_force))
    pred, corr = direct_run(model, transition, points)
    assert_same(by_stamp(out, 'predicted'), {1.0: (model.x0, model.P0), **pred})
    assert_same(by_stamp(out, 'corrected'), corr)
    # 'corrected' only at measurements; the time scale (mu) has the input points too
    assert sorted(by_stamp(out, 'corrected')) == measured[:-1]
    assert len([j for o in out for j in o.jumps]) == len(points) - 1
    _, _, values = session.diagnostics()
    assert values['inputs_received'] == values['inputs_accepted'] == len(inputs)
    assert values['accepted'] == len(measured) and values['gap_lengths_s'] == '17'
    assert values['mu_max_s'] == 2.5


def test_late_measurement_merges_into_an_input_point_or_takes_the_held_input():
    model = double_integrator()
    session = EstimatorSession(EstimatorConfig(model, transition='exact',
                                               nonpositive_is_gap=False))
    rng = np.random.default_rng(4)
    u = {t: rng.standard_normal(1) for t in (2.0, 3.0, 4.0)}
    y = {t: rng.standard_normal(1) for t in (1.0, 3.0, 3.5, 5.0, 6.0)}
    out = [session.add(1 * NS, y[1.0])]
    out += [session.add_input(int(t * NS), u[t]) for t in (2.0, 3.0, 4.0)]
    out += [session.add(5 * NS, y[5.0])]
    late = [session.add(3 * NS, y[3.0]), session.add(int(3.5 * NS), y[3.5])]
    assert [o.status for o in late] == ['inserted', 'inserted']
    out += [session.add(6 * NS, y[6.0])]
    points = [(1.0, y[1.0], np.zeros(1)), (2.0, None, u[2.0]), (3.0, y[3.0], u[3.0]),
              (3.5, y[3.5], u[3.0]), (4.0, None, u[4.0]), (5.0, y[5.0], u[4.0]),
              (6.0, y[6.0], u[4.0])]
    pred, corr = direct_run(model, 'exact', points)
    # the newest outputs and the last revision equal the direct run on the full scale
    assert_same(by_stamp(late[1:], 'corrected', revised=True),
                {t: corr[t] for t in (3.0, 3.5)})
    assert_same(by_stamp(late[1:], 'predicted', revised=True),
                {t: pred[t] for t in (3.5, 4.0, 5.0)})
    np.testing.assert_allclose(out[-1].estimates[0].x, corr[5.0][0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out[-1].estimates[1].x, pred[6.0][0], rtol=0, atol=1e-9)
    assert session.stats.inserted == 2


def test_bad_inputs_are_rejected_without_touching_the_state():
    session = EstimatorSession(EstimatorConfig(double_integrator(), nonpositive_is_gap=False,
                                               max_jump=30.0))
    session.add(1 * NS, 0.5)
    session.add_input(2 * NS, [0.1])
    before = session.kf.state()
    cases = [((3 * NS, [0.1, 0.2]), 'input_size'), ((3 * NS, [np.nan]), 'input_non_finite'),
             ((3 * NS, [np.inf]), 'input_non_finite'), ((0, [0.1]), 'input_zero_stamp'),
             ((int(1.5 * NS), [0.1]), 'input_late'), ((2 * NS, [0.3]), 'input_duplicate')]
    for args, reason in cases:
        out = session.add_input(*args)
        assert (out.status, out.reason) == ('rejected', reason) and not out.estimates
    np.testing.assert_array_equal(session.kf.state()[0], before[0])
    np.testing.assert_array_equal(session.u, [0.1])
    _, _, values = session.diagnostics()
    assert values['rejected_input_non_finite'] == 2 and values['rejected_input_late'] == 1
    assert values['inputs_received'] == 7 and values['inputs_accepted'] == 1
    # far ahead: a restart that keeps the input in force for the new time scale
    out = session.add_input(100 * NS, [0.7])
    assert (out.status, out.reason) == ('reset', 'forward_jump')
    assert session.pending() is None and session.u.tolist() == [0.7]
    # a model without B ignores inputs, counted
    plain = EstimatorSession(EstimatorConfig(owc()))
    assert plain.add_input(1 * NS, [1.0]).reason == 'no_input_matrix'
    assert plain.diagnostics()[2]['rejected_no_input_matrix'] == 1
