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
EstimatorSession (ROS-free) in order, against independent formulations.

The offline run of the core filter over the same time scale, a textbook scalar filter, a
direct run with the inputs held; and hostile streams (Hypothesis).
"""

from hostile_streams import check_psd, moves, SETTINGS, stamps_of, values
from hypothesis import given, strategies as st
import numpy as np
from owc_streams import collect, feed, measurements, OWC, power, STAMPS, T0, THETA
import pytest
from scalar_reference import C, check_step, close, D, P0, Reference, scalar_session, X0

from tskf_ros.core.diagnostic_status import ERROR, OK, WARN
from tskf_ros.core.linear_models import owc, run_filter, spring_mass
from tskf_ros.core.time_scales import discrete
from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, model_from_flat


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
    health, scale_status = session.diagnostics()
    times = scale_status.as_dict()
    assert times['Gaps'] == '2'
    assert times['Last gaps J (s)'] == f'{3 * scale:g} {4 * scale:g}'
    assert float(times['mu max (s)']) == 4.0 * scale
    assert health.as_dict()['Samples accepted'] == str(stamps.size)
    assert health.level == scale_status.level == OK


@pytest.mark.parametrize('transition', ['euler', 'exact'])
@pytest.mark.parametrize('message_variance', [False, True])
def test_in_order_samples_equal_a_textbook_scalar_filter(transition, message_variance):
    rng = np.random.default_rng(3)
    s = scalar_session(transition=transition, use_message_variance=message_variance,
                       gate=0.0)
    ref = Reference(transition=transition)
    # irregular intervals, a few gaps of several periods
    gaps = rng.choice([0.2, 0.5, 1.0, 1.0, 1.7, 4.0], size=60)
    stamps = T0 + np.concatenate(([0], np.cumsum(np.round(gaps * NS)))).astype(np.int64)
    stamps = [int(t) for t in stamps]
    ys = [float(v) for v in C * X0 + D + rng.normal(0, 1.0, len(stamps))]
    variances = [float(v) for v in rng.uniform(0.0, 0.5, len(stamps))]
    variances[::5] = [0.0] * len(variances[::5])         # some samples use R / mu
    first = s.add(stamps[0], ys[0], variances[0])
    assert first.estimates[0].x[0] == X0 and first.estimates[0].P[0, 0] == P0
    for k in range(1, len(stamps)):
        out = s.add(stamps[k], ys[k], variances[k])
        mu = (stamps[k] - stamps[k - 1]) / NS
        want = ref.step(mu, ys[k - 1], variances[k - 1] if message_variance else 0.0)
        check_step(out, stamps[k - 1], stamps[k], want)
        close(out.jumps[0].mu, mu)
    close(s.kf.x[0], ref.x)
    close(s.kf.P[0, 0], ref.P)
    health, times = (status.as_dict() for status in s.diagnostics())
    assert health['Samples accepted'] == health['Samples received'] == str(len(stamps))
    close(float(health['Covariance trace']), ref.P)
    close(float(times['mu max (s)']), max((b - a) / NS for a, b in zip(stamps, stamps[1:])))
    assert times['Gaps'] == str(sum(1 for a, b in zip(stamps, stamps[1:])
                                    if b - a > 1.5 * NS))


def test_non_regressive_step_is_refused_and_the_filter_goes_on():
    session = EstimatorSession(EstimatorConfig(spring_mass(), nonpositive_is_gap=False))
    session.add(1 * NS, 0.5)
    out = session.add(2 * NS, 0.5)                 # mu = 1: I + A singular (not regressive)
    assert out.reason == 'filter_error' and not out.estimates
    out = session.add(int(2.5 * NS), 0.5)          # mu = 1.5 is fine
    assert out.status == 'accepted' and [e.stamp_ns for e in out.estimates] == [
        1 * NS, int(2.5 * NS)]


def test_reconfigure_keeps_the_estimate():
    session = EstimatorSession(EstimatorConfig(owc()))
    feed(session, np.arange(1.0, 5.0), np.full(4, 200.0))
    x = session.kf.x.copy()
    session.reconfigure(EstimatorConfig(owc(), transition='exact'))
    np.testing.assert_array_equal(session.kf.x, x)
    assert session.kf.transition == 'exact'
    out = session.reconfigure(EstimatorConfig(spring_mass()))
    assert out.status == 'reset' and session.pending() is None


def check_estimator_outcome(out, limit):
    for e in out.estimates:
        assert 0 < e.stamp_ns <= MAX_STAMP_NS
        assert np.all(np.isfinite(e.x)) and float(np.max(np.abs(e.x))) <= limit
        check_psd(e.P, (e.kind, e.stamp_ns))
        assert np.sqrt(float(np.trace(e.P))) <= limit
    for j in out.jumps:
        assert 0 < j.stamp_ns < j.sigma_ns <= MAX_STAMP_NS and np.isfinite(j.mu)


@SETTINGS
@given(st.lists(st.tuples(moves, values), min_size=1, max_size=40))
def test_the_session_survives_anything_and_recovers(ops):
    # hostile stamps and values: nothing raises, nothing non-finite, beyond the limit or
    # not PSD is returned, and ordinary samples are used again within gate_patience + 1
    limit = 1e9
    session = EstimatorSession(EstimatorConfig(OWC, state_limit=limit))
    good = power(THETA)
    for stamp, value in zip(stamps_of([m for m, _ in ops]), [v for _, v in ops]):
        out = session.add(stamp, value, now_ns=T0)
        check_estimator_outcome(out, limit)
    for status in session.diagnostics(now_ns=T0):
        assert status.level in (OK, WARN, ERROR) and isinstance(status.message, str)
    # ordinary samples, 1 s apart, from well after anything that was sent
    start = MAX_STAMP_NS - 100 * NS
    outs = [session.add(start + k * NS, good, now_ns=T0) for k in range(12)]
    for out in outs:
        check_estimator_outcome(out, limit)
    # a reset or a gate lockout (at most gate_patience + 1 samples) and then accepted
    assert all(o.status == 'accepted' for o in outs[-5:]), [o.reason for o in outs]


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
    health, times = (status.as_dict() for status in session.diagnostics())
    assert health['Inputs received'] == health['Inputs accepted'] == str(len(inputs))
    assert health['Samples accepted'] == str(len(measured))
    assert times['Last gaps J (s)'] == '17' and times['mu max (s)'] == '2.5'


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
    x_before, P_before = session.kf.x, session.kf.P
    cases = [((3 * NS, [0.1, 0.2]), 'input_size'), ((3 * NS, [np.nan]), 'input_non_finite'),
             ((3 * NS, [np.inf]), 'input_non_finite'), ((0, [0.1]), 'input_zero_stamp'),
             ((int(1.5 * NS), [0.1]), 'input_late'), ((2 * NS, [0.3]), 'input_duplicate')]
    for args, reason in cases:
        out = session.add_input(*args)
        assert (out.status, out.reason) == ('rejected', reason) and not out.estimates
    assert session.kf.x is x_before and session.kf.P is P_before
    np.testing.assert_array_equal(session.u, [0.1])
    health = session.diagnostics()[0].as_dict()
    assert health['Rejected (input_non_finite)'] == '2'
    assert health['Rejected (input_late)'] == '1'
    assert health['Inputs received'] == '7' and health['Inputs accepted'] == '1'
    # far ahead: a restart that keeps the input in force for the new time scale
    out = session.add_input(100 * NS, [0.7])
    assert (out.status, out.reason) == ('reset', 'forward_jump')
    assert session.pending() is None and session.u.tolist() == [0.7]
    # a model without B ignores inputs, counted
    plain = EstimatorSession(EstimatorConfig(owc()))
    assert plain.add_input(1 * NS, [1.0]).reason == 'no_input_matrix'
    assert plain.diagnostics()[0].as_dict()['Rejected (no_input_matrix)'] == '1'


# what a fresh process feeds a session after its first samples: every other path of `add`
# (the node's config: the OWC model (3), period 1 ms); prints the kernel signatures each
# phase compiled (numba's public Dispatcher.signatures), as JSON
_PATHS_SCRIPT = """
import json
import math
from tskf_ros.core import jit
from tskf_ros.messages.estimator_interface import load_config
from tskf_ros.owc.session import EstimatorSession

jit.set_mode('wait')
session = EstimatorSession(load_config(overrides={'period': 0.001}).session)
MS, t = 1_000_000, 1_000_000_000_000


def signatures():
    return {f'{module}.{k.name}': len(k.dispatcher.signatures)
            for module, kernels in jit._kernels.items() for k in kernels
            if k.dispatcher is not None}


def run(samples):
    before = signatures()
    outcomes = [session.add(stamp, y) for stamp, y in samples]
    after = signatures()
    return {'outcomes': sorted({f'{o.status}:{o.reason}' for o in outcomes}),
            'compiled': sorted(k for k in after if after[k] != before.get(k, 0))}


phases = {'start': run([(t + k * MS, 165.0 + k % 3) for k in range(1, 101)])}
t += 100 * MS
for name, samples in [
        ('gap', [(t + MS, 0.0), (t + 2 * MS, 165.0)]),
        ('non_finite', [(t + 3 * MS, math.nan)]),
        ('gated', [(t + 4 * MS, 1e4), (t + 5 * MS, 165.0)]),
        ('jittered', [(t + 6 * MS + 7, 165.0), (t + 7 * MS - 5, 165.1)]),
        ('late', [(t + 6 * MS + 500_000, 165.0), (t + 8 * MS, 165.0)]),
        ('duplicate', [(t + 8 * MS, 165.0)]),
        ('forward_jump', [(t + 61_000 * MS, 165.0), (t + 61_001 * MS, 165.0)]),
        ('backward_jump', [(t + 8 * MS, 165.0), (t + 9 * MS, 165.0)]),
        ('long_interval', [(t + 509 * MS, 165.0), (t + 510 * MS, 165.0)])]:
    phases[name] = run(samples)
print(json.dumps(phases))
"""


def test_after_the_first_samples_no_path_of_add_compiles_a_kernel():
    # a kernel compiled (or loaded from numba's cache) in the middle of a stream stops the
    # node's executor for tens of ms (seconds with an empty cache) while its inputs queue:
    # every path a sample can take after the first ones runs the signatures those compiled
    import json
    import os
    import subprocess
    import sys
    result = subprocess.run([sys.executable, '-c', _PATHS_SCRIPT], capture_output=True,
                            text=True, env={**os.environ, 'TSKF_JIT': 'wait'}, timeout=600)
    assert result.returncode == 0, result.stderr
    phases = json.loads(result.stdout.strip().splitlines()[-1])
    assert phases.pop('start')['compiled'], 'the first samples compiled nothing: no test'
    outcomes = {o for phase in phases.values() for o in phase['outcomes']}
    assert {'gap:invalid_power', 'rejected:non_finite', 'rejected:gated', 'inserted:late',
            'rejected:duplicate', 'reset:forward_jump', 'reset:backward_jump'} <= outcomes
    assert {name: p['compiled'] for name, p in phases.items() if p['compiled']} == {}
