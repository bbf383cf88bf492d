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
What a sample must pass to be a point: stamps, readings, range, and the innovation gate.

The gate against its independent formulation: the Mahalanobis distance of the innovation
at the predictor, d^2 = e^2 / (C P C^T + R / period), e = y - C x - D (a textbook scalar
filter gives x, P).
"""

import math

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
from owc_streams import feed_seconds, OWC, owc_session, power, T0, THETA
import pytest
from scalar_reference import C, check_step, D, R, Reference, scalar_session, X0

from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, model_from_flat

SETTINGS = settings(derandomize=True, max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def test_bad_samples_are_rejected_without_touching_the_state():
    session = owc_session(max_future=5.0)
    assert session.add(1 * NS, 200.0).status == 'accepted'
    x_before, P_before = session.kf.x, session.kf.P
    cases = [((0, 200.0), 'zero_stamp'), ((2 * NS, float('nan')), 'non_finite'),
             ((2 * NS, float('inf')), 'non_finite'), ((2 * NS, 200.0, -1.0), 'bad_variance'),
             ((2 * NS, 0.0), 'invalid_power'), ((2 * NS, -3.0), 'invalid_power'),
             ((1 * NS, 200.0), 'duplicate')]
    for args, reason in cases:
        out = session.add(*args)
        assert out.reason == reason and not out.estimates
    out = session.add(20 * NS, 200.0, now_ns=10 * NS)
    assert out.reason == 'future'
    assert session.kf.x is x_before and session.kf.P is P_before
    counts = session.stats.rejected
    assert counts['non_finite'] == 2 and counts['invalid_power'] == 2 and counts['future'] == 1


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
    s = scalar_session(**extra)
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
    health = s.diagnostics()[0].as_dict()
    assert health[f'Rejected ({reason})'] == '1' and health['Samples received'] == '6'


def test_stamps_beyond_int32_seconds_are_rejected_and_counted():
    s = owc_session()
    top = (2**31 - 1) * NS
    assert s.add(top - NS, power(THETA)).status == 'accepted'
    out = s.add(top, power(THETA))
    assert out.status == 'accepted'
    assert max(e.stamp_ns for e in out.estimates) <= MAX_STAMP_NS
    out = s.add(MAX_STAMP_NS + 1, power(THETA))
    assert (out.status, out.reason) == ('rejected', 'stamp_range')


def test_measurement_range_rejects_readings_a_power_meter_cannot_give():
    s = owc_session(measurement_range=(0.0, 300.0))
    feed_seconds(s, range(3))
    out = s.add(T0 + 3 * NS, 350.0)
    assert (out.status, out.reason) == ('rejected', 'out_of_range')


# -- the innovation gate -----------------------------------------------------------------

@SETTINGS
@given(st.floats(0.0, 6.0), st.sampled_from([-1.0, 1.0]), st.sampled_from([1.0, 3.0, 5.0]))
def test_the_gate_rejects_exactly_beyond_its_mahalanobis_distance(k, sign, gate):
    s = scalar_session(gate=gate, gate_patience=100)
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
    assert s.diagnostics()[0].as_dict()['Rejected (gated)'] == '1'


def test_the_gate_is_the_mahalanobis_distance_of_the_innovation():
    # at the predictor (x, P) of the new stamp, d^2 = e^2 / (C P C^T + R / period)
    s = owc_session(gate=3.0)
    feed_seconds(s, range(5))
    x, P = s.points[-1].x, s.points[-1].P        # the predictor at t = 4 s ...
    probe = OWC.make_filter()
    probe.x, probe.P = x, P
    res = probe.step(1.0, s.points[-1].y)       # ... stepped to t = 5 s by hand
    S = float(OWC.C[0, 0] ** 2 * res.P_predicted[0, 0] + OWC.R[0, 0] / 1.0)
    centre = float(OWC.C[0, 0] * res.x_predicted[0] + OWC.D[0])
    inside = s.add(T0 + 5 * NS, centre + 2.9 * math.sqrt(S))
    assert inside.status == 'accepted'
    s2 = owc_session(gate=3.0)
    feed_seconds(s2, range(5))
    outside = s2.add(T0 + 5 * NS, centre + 3.1 * math.sqrt(S))
    assert outside.reason == 'gated'


def published(outcomes):
    """Every state and covariance entry the outcomes would publish."""
    return [v for o in outcomes for e in o.estimates for v in (*e.x, *np.ravel(e.P))]


def test_a_1e308_reading_is_gated_and_the_next_good_ones_are_used():
    # before: accepted; the corrected angle was -1.6e305 rad and the next 60 s of good
    # samples were refused (filter_error), with the diagnostics still OK
    s = owc_session()
    out = feed_seconds(s, range(10))
    bad = s.add(T0 + 10 * NS, 1e308)
    assert bad.status == 'rejected' and bad.reason == 'gated'
    out += feed_seconds(s, range(11, 20))
    assert all(o.status == 'accepted' for o in out)
    values = published(out)
    assert all(math.isfinite(v) and abs(v) < 10 for v in values)
    # the last corrected angle is back at the truth (within 5 sd of the steady filter)
    last = [e for o in out for e in o.estimates if e.kind == 'corrected'][-1]
    assert last.x[0] == pytest.approx(THETA, abs=5 * math.sqrt(last.P[0, 0]))
    assert s.diagnostics()[0].as_dict()['Rejected (gated)'] == '1'


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
    feed_seconds(s, range(10))
    out = feed_seconds(s, range(10, 30), theta=0.70, rng=np.random.default_rng(1))
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
    feed_seconds(s, range(5))
    out = feed_seconds(s, range(35, 45), rng=np.random.default_rng(2))
    assert [o.reason for o in out[:3]] == ['gated'] * 3
    assert (out[3].status, out[3].reason) == ('reset', 'gate_lockout')
    assert all(o.status == 'accepted' for o in out[4:])


def test_the_admission_of_a_run_at_once_is_check_sample_by_sample():
    # Admission.passes (the arrays of add_many) against Admission.check one sample at a time
    from tskf_ros.owc.session.admission import Admission
    rng = np.random.default_rng(5)
    n = 2000
    stamps = rng.choice([0, -5, T0, MAX_STAMP_NS, MAX_STAMP_NS + 1], n)
    ys = rng.choice([300.0, -1.0, 0.0, 1e308, math.inf, -math.inf, math.nan, 5e3], n)
    variances = rng.choice([0.0, 1.0, -1.0, math.inf, math.nan], n)
    nows = stamps + rng.choice([0, -3 * NS, 3 * NS], n)
    for range_, future, gap in (((), 0.0, True), ((0.0, 1000.0), 1.0, False)):
        config = EstimatorConfig(OWC, measurement_range=range_, max_future=future,
                                 nonpositive_is_gap=gap)
        admission = Admission(config, 1)
        expected = [admission.check(int(t), float(y), float(v), int(now)) is None
                    for t, y, v, now in zip(stamps, ys, variances, nows)]
        np.testing.assert_array_equal(admission.passes(stamps, ys, variances, nows), expected)
