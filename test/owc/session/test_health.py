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
A step whose state is absurd, non-finite or not PSD re-initialises the filter, says so.

The state limit against a textbook scalar filter: the session re-initialises at the very
sample where the reference's predictor crosses it.
"""

from dataclasses import replace

import numpy as np
from owc_streams import T0, task
import pytest
from scalar_reference import C, check_step, D, P0, Reference, scalar_session, X0

from tskf_ros.core.diagnostic_status import ERROR
from tskf_ros.core.linear_models import spring_mass
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, model_from_flat


def test_the_state_limit_reinitialises_at_the_sample_the_reference_crosses_it():
    limit = 10.0
    s = scalar_session(state_limit=limit, gate=0.0)
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
    assert task(s, 'filter health').level == ERROR
    # and it goes on from x0, P0 at that sample
    again = Reference()
    check_step(s.add(T0 + (j + 1) * NS, ys[j]), T0 + j * NS, T0 + (j + 1) * NS,
               again.step(1.0, ys[j]))


@pytest.mark.parametrize('which', ['P(t|t)', 'P(sigma(t))'])
def test_a_covariance_that_is_not_psd_is_refused(which):
    s = scalar_session(gate=0.0)
    for j in range(3):
        s.add(T0 + j * NS, C * X0 + D)
    kf = s.kf
    honest = kf.step

    def broken(*args, **kwargs):
        res = honest(*args, **kwargs)
        field = 'P_corrected' if which == 'P(t|t)' else 'P_predicted'
        return replace(res, **{field: np.array([[-1e-3]])})

    kf.step = broken
    out = s.add(T0 + 3 * NS, C * X0 + D)
    assert (out.status, out.reason) == ('reset', 'state_health')
    assert f'{which} lost positive semi-definiteness' in out.message
    assert [(e.kind, e.x[0], e.P[0, 0]) for e in out.estimates] == [('predicted', X0, P0)]
    assert s.kf is not kf                # a new filter, from x0, P0


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
    health = task(s, 'filter health')
    assert health.level == ERROR and 're-initialised itself' in health.message
    assert health.as_dict()['Resets (state_health)'] == '1'
    # the filter goes on from the sample that triggered it
    assert s.add(T0 + 34 * NS, 1.0).status == 'accepted'
    assert task(s, 'filter health').level != ERROR     # consumed by the update above


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


def test_the_health_of_a_run_at_once_is_checked_step_by_step():
    # health.sound_steps over a run's stacks against health.checked one step at a time:
    # the steps kept up to the first it refuses (indefinite P, |x| or trace P beyond the
    # limit, NaN), and their trace P(sigma)
    from tskf_ros.core.matrices import FilterError
    from tskf_ros.core.timescale_kalman import StepResult
    from tskf_ros.owc.session.health import checked, sound_steps
    rng = np.random.default_rng(9)
    for n in (1, 2, 3):
        for _ in range(50):
            K = 20
            M = rng.normal(size=(K, n, n))
            P_c = M @ M.transpose(0, 2, 1)
            P_p = P_c + 0.1 * np.eye(n)
            x_p = rng.normal(size=(K, n))
            k = rng.integers(K)
            bad = rng.integers(5)
            if bad == 0:
                P_c[k] -= 100.0 * np.eye(n)
            elif bad == 1:
                P_p[k] -= 100.0 * np.eye(n)
            elif bad == 2:
                x_p[k, -1] = 1e9
            elif bad == 3:
                P_p[k] *= 1e17
            else:
                x_p[k, 0] = np.nan
            count, traces = sound_steps(P_c, x_p, P_p, 1e8)
            expected = []
            for j in range(K):
                try:
                    expected.append(checked(StepResult(0.01, x_p[j], P_c[j], x_p[j], P_p[j],
                                                       x_p[j], P_p[j]), 1e8))
                except FilterError:
                    break
            assert count == len(expected)
            np.testing.assert_array_equal(traces, expected)
