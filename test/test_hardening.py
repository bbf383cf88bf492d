"""
Issue 10, the filters' half: absurd inputs and parameters neither crash nor wedge them.

Each test states the case that failed before the fix.  Sessions are driven directly (no
DDS); the node's cases are in test/nodes/test_timescale_estimator_parameters.py.
"""

import math

import numpy as np
import pytest

from tskf_ros.core import irregular
from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.led.alignment_session import AlignmentConfig, AlignmentSession
from tskf_ros.owc.estimator_session import (ConfigError, EstimatorConfig, EstimatorSession,
                                            model_from_flat)

T0 = 1_700_000_000 * NS
OWC = owc()
THETA = 0.5435                      # rad: the OWC model's x0, inside the linear range


def power(theta):
    """Cai eq. (2): the noise-free reading at angle theta."""
    return float(OWC.C[0, 0] * theta + OWC.D[0])


def owc_session(**extra):
    return EstimatorSession(EstimatorConfig(OWC, **extra))


def feed(session, seconds, theta=THETA, start=0.0, rng=None):
    """One reading per second at the seconds given (noise 10 mW, seeded)."""
    rng = rng or np.random.default_rng(0)
    return [session.add(T0 + int(round((start + t) * NS)),
                        power(theta) + 10.0 * rng.standard_normal())
            for t in seconds]


def published(outcomes):
    """Every state and covariance entry the outcomes would publish."""
    return [v for o in outcomes for e in o.estimates for v in (*e.x, *np.ravel(e.P))]


# -- finite but absurd measurements -----------------------------------------------------

def test_a_1e308_reading_is_gated_and_the_next_good_ones_are_used():
    # before: accepted; the corrected angle was -1.6e305 rad and the next 60 s of good
    # samples were refused (filter_error), with the diagnostics still OK
    s = owc_session()
    out = feed(s, range(10))
    bad = s.add(T0 + 10 * NS, 1e308)
    assert bad.status == 'rejected' and bad.reason == 'gated'
    out += feed(s, range(11, 20))
    assert all(o.status == 'accepted' for o in out)
    values = published(out)
    assert all(math.isfinite(v) and abs(v) < 10 for v in values)
    # the last corrected angle is back at the truth (within 5 sd of the steady filter)
    last = [e for o in out for e in o.estimates if e.kind == 'corrected'][-1]
    assert last.x[0] == pytest.approx(THETA, abs=5 * math.sqrt(last.P[0, 0]))
    level, _, values = s.diagnostics()
    assert values['rejected_gated'] == 1


def test_the_gate_is_the_mahalanobis_distance_of_the_innovation():
    # an independent formulation: at the predictor (x, P) of the new stamp,
    # d^2 = e^2 / (C P C^T + R / period), e = y - C x - D
    s = owc_session(gate=3.0)
    feed(s, range(5))
    x, P = s.points[-1].x, s.points[-1].P        # the predictor at t = 4 s ...
    s.kf.set_state(x, P)
    res = s.kf.step(1.0, s.points[-1].y)         # ... stepped to t = 5 s by hand
    S = float(OWC.C[0, 0] ** 2 * res.P_predicted[0, 0] + OWC.R[0, 0] / 1.0)
    centre = float(OWC.C[0, 0] * res.x_predicted[0] + OWC.D[0])
    s.kf.set_state(x, P)
    inside = s.add(T0 + 5 * NS, centre + 2.9 * math.sqrt(S))
    assert inside.status == 'accepted'
    s2 = owc_session(gate=3.0)
    feed(s2, range(5))
    outside = s2.add(T0 + 5 * NS, centre + 3.1 * math.sqrt(S))
    assert outside.reason == 'gated'


def slow_owc(**extra):
    """Return a session of Cai's eq. (2) over a random-walk angle (A = 0, Q = 1e-3 rad^2/s)."""
    model = model_from_flat(A=[0.0], C=[-637.35], D=[511.97], Q=[1e-3], R=[100.0],
                            x0=[THETA], P0=[0.01], name='owc')
    return EstimatorSession(EstimatorConfig(model, **extra))


def test_a_rejected_sample_widens_the_gate_so_the_filter_cannot_lock_itself_out():
    # the angle really jumps from 0.5435 to 0.70 rad (a reading 100 mW lower, 4.4 sd of
    # the one-second prediction): the first readings after the jump fail a 3 sd gate,
    # but each leaves a longer gap and a wider prediction, until one passes
    s = slow_owc(gate=3.0, gate_patience=100)
    feed(s, range(10))
    out = feed(s, range(10, 30), theta=0.70, rng=np.random.default_rng(1))
    reasons = [o.reason for o in out]
    assert reasons[0] == 'gated'
    accepted = [i for i, o in enumerate(out) if o.status == 'accepted']
    assert accepted and accepted[0] <= 10
    assert all(o.status == 'accepted' for o in out[accepted[0]:])
    last = [e for e in out[-1].estimates if e.kind == 'corrected'][-1]
    assert last.x[0] == pytest.approx(0.70, abs=0.05)


def test_gate_patience_ends_a_lockout_of_an_unstable_model():
    # Cai's A = 1 grows the prediction's mean as fast as its deviation over a gap: after
    # a 30 s outage the prediction is 31 x theta and every reading fails the gate
    s = owc_session(gate=3.0, gate_patience=3)
    feed(s, range(5))
    out = feed(s, range(35, 45), rng=np.random.default_rng(2))
    assert [o.reason for o in out[:3]] == ['gated'] * 3
    assert (out[3].status, out[3].reason) == ('reset', 'gate_lockout')
    assert all(o.status == 'accepted' for o in out[4:])


def test_measurement_range_rejects_readings_a_power_meter_cannot_give():
    s = owc_session(measurement_range=(0.0, 300.0))
    feed(s, range(3))
    out = s.add(T0 + 3 * NS, 350.0)
    assert (out.status, out.reason) == ('rejected', 'out_of_range')
    with pytest.raises(ConfigError, match='measurement_range'):
        EstimatorConfig(OWC, measurement_range=(5.0, 1.0))


def test_an_absurd_step_reinitialises_the_filter_and_the_diagnostics_say_error():
    # A = 2 per s with the exact transition: a 30 s gap multiplies the state by e^60
    model = model_from_flat(A=[2.0], C=[1.0], Q=[1.0], R=[1.0], x0=[1.0], P0=[1.0])
    s = EstimatorSession(EstimatorConfig(model, transition='exact', max_jump=100.0,
                                         nonpositive_is_gap=False, gate=0.0))
    for k in range(3):
        s.add(T0 + k * NS, 1.0)
    out = s.add(T0 + 33 * NS, 1.0)
    assert (out.status, out.reason) == ('reset', 'state_health')
    assert 'state_limit' in out.message
    level, message, values = s.diagnostics()
    assert level == 'ERROR' and 're-initialised itself' in message
    assert values['resets_state_health'] == 1
    # the filter goes on from the sample that triggered it
    assert s.add(T0 + 34 * NS, 1.0).status == 'accepted'
    assert s.diagnostics()[0] != 'ERROR'       # consumed by the report above


# -- crashes from valid parameters ------------------------------------------------------

def test_a_600_s_gap_with_max_jump_1000_does_not_overflow():
    # before: OverflowError in scalar_fixed_point (a ** (2 * kappa))
    s = owc_session(max_jump=1000.0)
    feed(s, range(5))
    out = s.add(T0 + 605 * NS, power(THETA))
    # 601 x theta predicted (A = 1, Euler): the true reading fails the gate, no exception
    assert (out.status, out.reason) == ('rejected', 'gated')
    s = owc_session(max_jump=1000.0, gate=0.0)
    feed(s, range(5))
    assert s.add(T0 + 605 * NS, power(THETA)).status == 'accepted'
    level, message, values = s.diagnostics()
    assert values['theorem2_peak_bound_high'] == math.inf   # (1 + 1)^1200: no finite bound
    assert math.isfinite(values['theorem2_peak_bound_low'])


def test_scalar_fixed_point_for_a_huge_interval_is_inf_not_an_overflow():
    # closed form check for a small kappa, then the limit
    a, c, q, r = 2.0, 1.0, 1.0, 1.0
    X = irregular.scalar_fixed_point(a, c, q, r, 3)
    # X = f^3(g(X)) with g(X) = r X / (c^2 X + r), f(Y) = a^2 Y + q
    Y = r * X / (c * c * X + r)
    for _ in range(3):
        Y = a * a * Y + q
    assert Y == pytest.approx(X, rel=1e-12)
    assert irregular.scalar_fixed_point(a, c, q, r, 10**9) == math.inf
    # |a| < 1: a^{2 kappa} -> 0, so X = f^kappa(g(X)) -> q / (1 - a^2)
    assert irregular.scalar_fixed_point(0.5, c, q, r, 10**9) == pytest.approx(
        q / (1 - 0.25), rel=1e-12)


def test_config_is_validated_by_what_it_does():
    # before: accepted, then almost every sample was refused
    with pytest.raises(ConfigError, match='a step of mu = (period = )?1 s from x0, P0'):
        EstimatorConfig(model_from_flat(A=[1.0], C=[-637.35], D=[511.97], Q=[1e308],
                                        R=[100.0], x0=[0.5], P0=[0.01]))
    with pytest.raises(ConfigError, match='initial state is absurd'):
        EstimatorConfig(model_from_flat(A=[1.0], C=[-637.35], D=[511.97], Q=[1.0],
                                        R=[100.0], x0=[1e308], P0=[0.01]))


# -- CPU: the interval checks cost the same whatever the interval ----------------------

def test_interval_checks_cost_does_not_grow_with_the_interval(monkeypatch):
    # before: each new interval re-checked every interval up to the largest (80 ms per
    # sample at period 1 ms with gaps up to 50 s).  Count the resonance tests instead of
    # timing: a new interval costs at most one test per eigenvalue pair.
    calls = []
    real = irregular.resonate

    def counting(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(irregular.intervals, 'resonate', counting)
    # a drogue-like model with two unit eigenvalues on the circle (a rotation): 1 pair
    model = model_from_flat(A=[0.0, -1.0, 1.0, 0.0], C=[1.0, 0.0], Q=[1e-3, 0, 0, 1e-3],
                            R=[1.0], x0=[0.0, 0.0], P0=[1.0, 0.0, 0.0, 1.0])
    s = EstimatorSession(EstimatorConfig(model, period=0.001, max_jump=100.0, gate=0.0,
                                         nonpositive_is_gap=False, history_window=0.0,
                                         max_backward=0.0))
    t = T0
    s.add(t, 0.1)
    before = len(calls)
    rng = np.random.default_rng(5)
    gaps = rng.integers(1, 50_000, size=40)          # 1 ms .. 50 s, in periods
    for g in gaps:
        t += int(g) * 1_000_000
        s.add(t, 0.1)
    per_new_interval = (len(calls) - before) / len(set(gaps.tolist()))
    assert per_new_interval <= 1


# -- stamps a ROS message cannot hold ---------------------------------------------------

def test_stamps_beyond_int32_seconds_are_rejected_and_counted():
    s = owc_session()
    top = (2**31 - 1) * NS
    assert s.add(top - NS, power(THETA)).status == 'accepted'
    out = s.add(top, power(THETA))
    assert out.status == 'accepted'
    assert max(e.stamp_ns for e in out.estimates) <= MAX_STAMP_NS
    out = s.add(MAX_STAMP_NS + 1, power(THETA))
    assert (out.status, out.reason) == ('rejected', 'stamp_range')
    a = AlignmentSession(AlignmentConfig())
    assert a.add(MAX_STAMP_NS + 1, 1.0).reason == 'stamp_range'


# -- revisions --------------------------------------------------------------------------

def test_revisions_come_in_stamp_order_and_a_later_one_supersedes():
    s = owc_session()
    feed(s, [0, 1, 2, 4, 5, 7, 8])
    first = s.add(T0 + 3 * NS, power(THETA))          # late: revises 3 .. 8
    second = s.add(T0 + 6 * NS, power(THETA) + 5.0)   # late: revises 6 .. 8 again
    for out in (first, second):
        assert out.status == 'inserted'
        for kind in ('predicted', 'corrected'):
            stamps = [e.stamp_ns for e in out.estimates if e.kind == kind]
            assert stamps == sorted(set(stamps))        # once each, in order, per revision
    again = {e.stamp_ns for e in second.estimates} & {e.stamp_ns for e in first.estimates}
    assert again            # the same stamps revised twice: the later message wins
    newest = {(e.kind, e.stamp_ns): e.x[0] for o in (first, second) for e in o.estimates}
    assert newest[('predicted', T0 + 8 * NS)] == pytest.approx(s.points[-1].x[0], rel=1e-12)


# -- diagnostics that tell the truth ----------------------------------------------------

def test_silent_input_is_an_error_and_a_slow_one_a_warning():
    s = owc_session(stale_timeout=10.0, min_rate_fraction=0.5, rate_window=10.0)
    now = T0
    for k in range(12):                               # 1 Hz: OK
        s.add(now, power(THETA), now_ns=now)
        now += NS
    assert s.diagnostics(now_ns=now)[0] == 'OK'
    for k in range(6):                                # 0.25 Hz over 10 s: WARN
        now += 4 * NS
        s.add(now - 2 * NS, power(THETA), now_ns=now)
    level, message, values = s.diagnostics(now_ns=now)
    assert level == 'WARN' and 'below 0.5' in message
    assert values['input_rate_hz'] == pytest.approx(0.2, abs=0.11)
    level, message, _ = s.diagnostics(now_ns=now + 11 * NS)   # nothing for 11 s
    assert level == 'ERROR' and 'no input' in message
    fresh = owc_session(stale_timeout=10.0)
    fresh.diagnostics(now_ns=T0)
    assert fresh.diagnostics(now_ns=T0 + 10 * NS)[0] == 'ERROR'   # never any input


# -- the alignment session ---------------------------------------------------------------

def aligner(**extra):
    return AlignmentSession(AlignmentConfig(**extra))


def test_alignment_gates_a_1e308_intensity_and_the_base_stays_in_its_limits():
    # before: the base command went to about -8e305 rad, and stayed there
    a = aligner()
    stamps = [T0 + k * NS // 20 for k in range(400)]
    outs = []
    for k, t in enumerate(stamps):
        z = 1e308 if k == 200 else 2.0
        outs.append(a.add(t, z))
    assert outs[200].status == 'missing' and outs[200].reason == 'gated'
    commands = [o.command for o in outs if o.command is not None]
    assert all(-360.0 <= c <= 360.0 for c in commands)
    turns = np.abs(np.diff([0.0] + commands))
    assert turns.max() <= 45.0 + 1e-9
    assert outs[-1].status == 'used'


def test_alignment_commands_are_clamped_and_the_ekf_told():
    a = aligner(max_step=1.0, base_limits=(-3.0, 3.0), x0=(2.0, 20.0))
    outs = [a.add(T0 + k * NS // 20, 2.0) for k in range(50)]
    cmds = [o.command for o in outs]
    assert all(-3.0 - 1e-12 <= c <= 3.0 + 1e-12 for c in cmds)
    assert max(abs(b - c) for b, c in zip([0.0] + cmds, cmds)) <= 1.0 + 1e-12
    assert a.diagnostics()[2]['commands_clamped'] > 0
    with pytest.raises(ValueError, match='base_initial'):
        AlignmentConfig(base_initial=10.0, base_limits=(-3.0, 3.0))


def test_alignment_restarts_itself_on_an_absurd_state_and_reports_error():
    a = aligner(gate=0.0)                            # no gate: 1e200 V reaches the EKF
    outs = [a.add(T0 + k * NS // 20, 2.0) for k in range(3)]
    outs.append(a.add(T0 + 3 * NS // 20, 1e200))
    assert outs[-1].reason == 'filter_error' and 'state_limit' in outs[-1].message
    level, message, values = a.diagnostics()
    assert level == 'ERROR' and values['resets_state_health'] == 1
