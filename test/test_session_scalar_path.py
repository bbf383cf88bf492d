"""
The estimator session's plain-float path (n = p = 1) keeps every check's effect.

EstimatorSession.add takes an ordinary sample of a scalar model on plain floats and
hands anything else to the general path.  Each test states a check and asserts its
effect in numbers against a scalar Kalman filter written here in textbook form
(S = c^2 P + R_d, L = P c / S, Joseph form, then F and Q_d), not the filter under test:

- in-order estimates, with the model's R / mu or the sample's own variance;
- the innovation gate at the boundary (Hypothesis), and the gap a gated sample leaves;
- NaN / inf / bad variance / bad stamps refused with their reason, nothing moved;
- the state limit re-initialises at the very sample the reference crosses it;
- a step whose covariance is not positive semi-definite is refused;
- on hostile streams (Hypothesis) the float path and the general path give the same
  outcomes, bit for bit, and the same diagnostics.
"""

import math

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.owc.estimator_session import EstimatorConfig, EstimatorSession, model_from_flat

T0 = 1_700_000_000 * NS
# a stable scalar model with an offset; readings of either sign are points
A, C, D, Q, R, X0, P0 = -0.3, 2.0, 5.0, 0.5, 0.2, 1.0, 0.5
MODEL = model_from_flat(A=[A], C=[C], D=[D], Q=[Q], R=[R], x0=[X0], P0=[P0])
SETTINGS = settings(derandomize=True, max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
REL = 1e-10                 # textbook form against Table 3 term by term: rounding only


class Reference:
    """The scalar Kalman filter of the model, textbook form, on plain floats."""

    def __init__(self, a=A, c=C, d=D, q=Q, r=R, x=X0, P=P0, transition='euler'):
        self.a, self.c, self.d, self.q, self.r = a, c, d, q, r
        self.x, self.P, self.transition = x, P, transition

    def transition_of(self, mu):
        """(F, Q_d) over mu: I + mu A, mu Q, or e^{a mu} and its integral."""
        if self.transition == 'euler':
            return 1.0 + mu * self.a, mu * self.q
        F = math.exp(self.a * mu)
        return F, self.q * (F * F - 1.0) / (2.0 * self.a)

    def step(self, mu, y, variance=0.0):
        """Correct at t with y (R_d = variance if > 0, else R / mu), predict sigma(t)."""
        c, P = self.c, self.P
        rd = variance if variance > 0 else self.r / mu
        S = c * c * P + rd
        L = P * c / S
        x_c = self.x + L * (y - c * self.x - self.d)
        P_c = (1.0 - L * c) ** 2 * P + L * L * rd
        F, Qd = self.transition_of(mu)
        self.x, self.P, self.corrected = F * x_c, F * F * P_c + Qd, (x_c, P_c)
        return x_c, P_c, self.x, self.P

    def gate_distance(self, y, period):
        """Mahalanobis distance of y at the predictor, with R / period."""
        return abs(y - self.c * self.x - self.d) / math.sqrt(
            self.c * self.c * self.P + self.r / period)


def session(**extra):
    extra.setdefault('nonpositive_is_gap', False)
    return EstimatorSession(EstimatorConfig(MODEL, **extra))


def close(got, want):
    assert got == pytest.approx(want, rel=REL, abs=1e-300), (got, want)


def check_step(out, t, sigma, ref_values):
    """Check the outcome of an ordinary sample: corrected at t, predicted at sigma."""
    x_c, P_c, x_p, P_p = ref_values
    assert out.status == 'accepted', (out.reason, out.message)
    (corr, pred), (jump,) = out.estimates, out.jumps
    assert (corr.kind, corr.stamp_ns, pred.kind, pred.stamp_ns) == (
        'corrected', t, 'predicted', sigma)
    assert corr.x.shape == (1,) and corr.P.shape == (1, 1) and pred.P.shape == (1, 1)
    for got, want in ((corr.x[0], x_c), (corr.P[0, 0], P_c), (pred.x[0], x_p),
                      (pred.P[0, 0], P_p)):
        close(got, want)
    assert (jump.stamp_ns, jump.sigma_ns) == (t, sigma)


def count_general(s):
    """Count the samples the float path hands to the general one."""
    calls = []
    general = s._add

    def counted(*args):
        calls.append(args[0])
        return general(*args)

    s._add = counted
    return calls


@pytest.mark.parametrize('transition', ['euler', 'exact'])
@pytest.mark.parametrize('message_variance', [False, True])
def test_in_order_samples_equal_a_textbook_scalar_filter(transition, message_variance):
    rng = np.random.default_rng(3)
    s = session(transition=transition, use_message_variance=message_variance, gate=0.0)
    ref = Reference(transition=transition)
    # irregular intervals, a few gaps of several periods
    gaps = rng.choice([0.2, 0.5, 1.0, 1.0, 1.7, 4.0], size=60)
    stamps = T0 + np.concatenate(([0], np.cumsum(np.round(gaps * NS)))).astype(np.int64)
    stamps = [int(t) for t in stamps]
    ys = [float(v) for v in C * X0 + D + rng.normal(0, 1.0, len(stamps))]
    variances = [float(v) for v in rng.uniform(0.0, 0.5, len(stamps))]
    variances[::5] = [0.0] * len(variances[::5])         # some samples use R / mu
    general = count_general(s)
    first = s.add(stamps[0], ys[0], variances[0])
    assert first.estimates[0].x[0] == X0 and first.estimates[0].P[0, 0] == P0
    for k in range(1, len(stamps)):
        out = s.add(stamps[k], ys[k], variances[k])
        mu = (stamps[k] - stamps[k - 1]) / NS
        want = ref.step(mu, ys[k - 1], variances[k - 1] if message_variance else 0.0)
        check_step(out, stamps[k - 1], stamps[k], want)
        close(out.jumps[0].mu, mu)
    assert general == [stamps[0]]           # only the first sample took the general path
    close(s.kf.x[0], ref.x)
    close(s.kf.P[0, 0], ref.P)
    _, _, values = s.diagnostics()
    assert values['accepted'] == len(stamps) and values['received'] == len(stamps)
    close(values['covariance_trace'], ref.P)
    close(values['mu_max_s'], max((b - a) / NS for a, b in zip(stamps, stamps[1:])))
    assert values['gaps'] == sum(1 for a, b in zip(stamps, stamps[1:]) if b - a > 1.5 * NS)


@SETTINGS
@given(st.floats(0.0, 6.0), st.sampled_from([-1.0, 1.0]), st.sampled_from([1.0, 3.0, 5.0]))
def test_the_gate_rejects_exactly_beyond_its_mahalanobis_distance(k, sign, gate):
    s = session(gate=gate, gate_patience=100)
    ref = Reference()
    ys = [C * X0 + D + 0.3 * (-1) ** j for j in range(6)]
    for j, y in enumerate(ys):
        s.add(T0 + j * NS, y)
        if j:
            ref.step(1.0, ys[j - 1])
    # the predictor at t = 6 s, from the reading at 5 s
    probe = Reference(x=ref.x, P=ref.P)
    probe.step(1.0, ys[-1])
    sd = math.sqrt(C * C * probe.P + R / 1.0)
    y = C * probe.x + D + sign * k * sd
    if abs(probe.gate_distance(y, 1.0) - gate) < 1e-6:
        return                              # too close to the boundary to tell rounding
    x_before, P_before = s.kf.x, s.kf.P
    out = s.add(T0 + 6 * NS, y)
    if probe.gate_distance(y, 1.0) <= gate:
        check_step(out, T0 + 5 * NS, T0 + 6 * NS, ref.step(1.0, ys[-1]))
        return
    assert (out.status, out.reason) == ('rejected', 'gated')
    assert 'standard deviations' in out.message and not out.estimates
    assert s.kf.x is x_before and s.kf.P is P_before
    # not a point: the next sample steps over the whole 2 s from 5 s
    check_step(s.add(T0 + 7 * NS, ys[-1]), T0 + 5 * NS, T0 + 7 * NS, ref.step(2.0, ys[-1]))
    assert s.diagnostics()[2]['rejected_gated'] == 1


BAD = [
    # (value, variance, stamp offset from the newest in s or an absolute stamp, reason)
    (math.nan, 0.0, 1.0, 'non_finite'),
    (math.inf, 0.0, 1.0, 'non_finite'),
    (-math.inf, 0.0, 1.0, 'non_finite'),
    (7.0, math.nan, 1.0, 'bad_variance'),
    (7.0, -1e-3, 1.0, 'bad_variance'),
    (7.0, math.inf, 1.0, 'bad_variance'),
    (7.0, 0.0, 0.0, 'duplicate'),
    (7.0, 0.0, ('at', 0), 'zero_stamp'),
    (7.0, 0.0, ('at', -NS), 'zero_stamp'),
    (7.0, 0.0, ('at', MAX_STAMP_NS + 1), 'stamp_range'),
    (7.0, 0.0, 1.0, 'future'),
    (-7.0, 0.0, 1.0, 'invalid_power'),
    (400.0, 0.0, 1.0, 'out_of_range'),
]


@pytest.mark.parametrize('value, variance, where, reason', BAD)
def test_bad_samples_are_refused_with_their_reason_and_move_nothing(value, variance, where,
                                                                    reason):
    extra = {'future': {'max_future': 0.5}, 'invalid_power': {'nonpositive_is_gap': True},
             'out_of_range': {'measurement_range': (-100.0, 100.0)}}.get(reason, {})
    s = session(**extra)
    ref = Reference()
    ys = [C * X0 + D + 0.1 * j for j in range(4)]
    for j, y in enumerate(ys):
        s.add(T0 + j * NS, y, now_ns=T0 + j * NS)
        if j:
            ref.step(1.0, ys[j - 1])
    x_before, P_before, points = s.kf.x, s.kf.P, list(s.points)
    newest = T0 + 3 * NS
    stamp = where[1] if isinstance(where, tuple) else newest + int(where * NS)
    out = s.add(stamp, value, variance, now_ns=newest)
    expected = 'gap' if reason == 'invalid_power' else 'rejected'
    assert (out.status, out.reason) == (expected, reason), out.message
    assert out.message and '\n' not in out.message and not out.estimates and not out.jumps
    assert s.kf.x is x_before and s.kf.P is P_before and list(s.points) == points
    # the next ordinary sample steps from the newest point as if the bad one never came
    check_step(s.add(newest + 2 * NS, ys[-1], now_ns=newest + 2 * NS), newest,
               newest + 2 * NS, ref.step(2.0, ys[-1]))
    _, _, values = s.diagnostics()
    assert values[f'rejected_{reason}'] == 1 and values['received'] == 6


def test_the_state_limit_reinitialises_at_the_sample_the_reference_crosses_it():
    limit = 10.0
    s = session(state_limit=limit, gate=0.0)
    ref = Reference()
    ys = [C * 0.5 * j + D for j in range(40)]          # a ramp: x runs past the limit
    s.add(T0, ys[0])
    for j in range(1, len(ys)):
        _, _, x_p, P_p = ref.step(1.0, ys[j - 1])
        out = s.add(T0 + j * NS, ys[j])
        if abs(x_p) > limit or not P_p <= limit * limit:
            break
        check_step(out, T0 + (j - 1) * NS, T0 + j * NS, (*ref.corrected, x_p, P_p))
    else:
        pytest.fail('the reference never crossed the limit')
    assert (out.status, out.reason) == ('reset', 'state_health') and 'state_limit' in out.message
    (start,) = out.estimates
    assert (start.kind, start.stamp_ns, start.x[0], start.P[0, 0]) == (
        'predicted', T0 + j * NS, X0, P0)
    assert s.diagnostics()[0] == 'ERROR'
    # and it goes on from x0, P0 at that sample
    again = Reference()
    check_step(s.add(T0 + (j + 1) * NS, ys[j]), T0 + j * NS, T0 + (j + 1) * NS,
               again.step(1.0, ys[j]))


@pytest.mark.parametrize('which', ['P(t|t)', 'P(sigma(t))'])
def test_a_covariance_that_is_not_psd_is_refused(which):
    s = session(gate=0.0)
    for j in range(3):
        s.add(T0 + j * NS, C * X0 + D)
    kf = s.kf
    honest = kf.scalar_step

    def broken(*args):
        x_c, P_c, x_p, P_p, e, S = honest(*args)
        if which == 'P(t|t)':
            return x_c, -1e-3, x_p, P_p, e, S
        return x_c, P_c, x_p, -1e-3, e, S

    kf.scalar_step = broken              # both paths step through it
    out = s.add(T0 + 3 * NS, C * X0 + D)
    assert (out.status, out.reason) == ('reset', 'state_health')
    assert f'{which} lost positive semi-definiteness' in out.message
    assert [(e.kind, e.x[0], e.P[0, 0]) for e in out.estimates] == [('predicted', X0, P0)]
    assert s.kf is not kf                # a new filter, from x0, P0


# -- the float path and the general path decide alike ------------------------------------

INPUT_MODEL = model_from_flat(A=[-0.5], B=[1.0], C=[1.0], Q=[0.1], R=[0.5], x0=[0.0],
                              P0=[1.0])
hostile_values = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 5e-324, 1e308,
                     -1e308, 1e-300]),
    st.floats(-20.0, 20.0))
variances = st.sampled_from([0.0, 0.0, 0.25, 1e-3, 5e-324, 1e308, math.nan, -1.0, 4.0])
steps_ns = st.sampled_from([NS, NS, NS // 2, NS // 3, 2 * NS, 7 * NS, 0, -NS, -3 * NS,
                            -10**4 * NS, 70 * NS, 10**6 * NS])
event = st.tuples(st.sampled_from(['add', 'add', 'add', 'input']), steps_ns, hostile_values,
                  variances)


def same_outcome(a, b):
    assert (a.status, a.reason, a.message) == (b.status, b.reason, b.message)
    assert len(a.estimates) == len(b.estimates) and len(a.jumps) == len(b.jumps)
    for e, f in zip(a.estimates, b.estimates):
        assert (e.kind, e.stamp_ns, e.revised) == (f.kind, f.stamp_ns, f.revised)
        assert e.x.shape == f.x.shape and e.P.shape == f.P.shape
        assert e.x.tolist() == f.x.tolist() and e.P.tolist() == f.P.tolist()
    for j, k in zip(a.jumps, b.jumps):
        assert (j.stamp_ns, j.sigma_ns, j.revised) == (k.stamp_ns, k.sigma_ns, k.revised)


@SETTINGS
@given(st.lists(event, min_size=1, max_size=50), st.sampled_from(['euler', 'exact']),
       st.booleans(), st.booleans(), st.sampled_from([0.0, 2.0]))
def test_float_path_and_general_path_give_the_same_outcomes(events, transition, inputs,
                                                            message_variance, gate):
    model = INPUT_MODEL if inputs else MODEL
    config = EstimatorConfig(model, transition=transition, gate=gate, gate_patience=2,
                             use_message_variance=message_variance, state_limit=1e6,
                             max_jump=60.0, nonpositive_is_gap=not inputs, max_future=100.0)
    fast, general = EstimatorSession(config), EstimatorSession(config)
    general._append_scalar = lambda *args: None
    newest = T0
    for kind, step, value, variance in events:
        stamp = newest + step
        now = T0 + 50 * NS
        if kind == 'input':
            a, b = fast.add_input(stamp, [value]), general.add_input(stamp, [value])
        else:
            a = fast.add(stamp, value, variance, now_ns=now)
            b = general.add(stamp, value, variance, now_ns=now)
        same_outcome(a, b)
        if a.status != 'rejected':
            newest = max(newest, stamp) if step > -10**4 * NS else stamp
    assert fast.kf.x.tolist() == general.kf.x.tolist()
    assert fast.kf.P.tolist() == general.kf.P.tolist()
    assert [p.stamp_ns for p in fast.points] == [p.stamp_ns for p in general.points]
    assert fast.diagnostics(now_ns=now) == general.diagnostics(now_ns=now)
