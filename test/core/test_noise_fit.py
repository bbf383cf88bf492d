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
Maximum likelihood of Q and R (tskf_ros.core.noise_fit): the likelihood and the NIS check.

The likelihood of a trace is checked against a scalar Kalman filter written out here, the
NIS band against the chi-square distribution of the mean.
"""

from dataclasses import replace

import numpy as np
import pytest

from tskf_ros.core import noise_fit
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.noise_fit import (negative_log_likelihood, run_trace, StepRecord,
                                     trace_log_likelihood)
from tskf_ros.core.timescale_kalman import FilterError


def scalar_log_likelihood(mu, y, variance, a, q, r, x0, p0):
    """
    Return log L of a predictive scalar KF written out: F = 1 + mu a, Q_d = mu q.

    R_d = r / mu, or the sample's own variance where it is > 0 (use_message_variance).
    """
    x, P, ll = x0, p0, 0.0
    for m, yk, v in zip(mu, y, variance):
        Rd = v if v > 0 else r / m
        S = P + Rd
        e = yk - x
        ll += -0.5 * (np.log(2 * np.pi * S) + e * e / S)
        K = P / S
        x, P = x + K * e, P - K * P
        F = 1.0 + m * a
        x, P = F * x, F * P * F + m * q
    return ll


def test_log_likelihood_is_a_scalar_filter_written_out():
    # x(t_{k+1}) = (1 + mu_k a) x(t_k) + sqrt(mu_k q) w_k, y(t_k) = x(t_k) + sqrt(r / mu_k) v_k
    rng = np.random.default_rng(5)
    a, q, r = -0.1, 0.04, 0.25
    mu = np.where(rng.random(400) < 0.1, rng.integers(2, 7, 400), 1).astype(float)
    x, y = 0.0, np.empty(mu.size)
    for k in range(mu.size):
        y[k] = x + np.sqrt(r / mu[k]) * rng.standard_normal()
        x = (1.0 + mu[k] * a) * x + np.sqrt(mu[k] * q) * rng.standard_normal()
    variance = np.where(rng.random(mu.size) < 0.2, rng.uniform(0.1, 0.5, mu.size), 0.0)
    trace = [[StepRecord(m, np.array([yk]), variance=v) for m, yk, v in zip(mu, y, variance)]]
    for q_try, r_try in ((q, r), (1.0, 1.0), (0.01, 2.0)):
        model = LinearModel('sim', A=np.array([[a]]), C=np.array([[1.0]]),
                            Q=np.array([[q_try]]), R=np.array([[r_try]]), x0=np.array([0.0]),
                            P0=np.array([[1.0]]))
        want = scalar_log_likelihood(mu, y, variance, a, q_try, r_try, 0.0, 1.0)
        assert -negative_log_likelihood(model, 'euler', trace) == pytest.approx(want, rel=1e-10)
        inn = run_trace(model, 'euler', trace)
        assert inn.count == mu.size and inn.log_likelihood() == pytest.approx(want, rel=1e-10)
    # two segments: each starts again from x0, P0
    half = [trace[0][:200], trace[0][200:]]
    want = (scalar_log_likelihood(mu[:200], y[:200], variance[:200], a, q, r, 0.0, 1.0)
            + scalar_log_likelihood(mu[200:], y[200:], variance[200:], a, q, r, 0.0, 1.0))
    model = LinearModel('sim', A=np.array([[a]]), C=np.array([[1.0]]), Q=np.array([[q]]),
                        R=np.array([[r]]), x0=np.array([0.0]), P0=np.array([[1.0]]))
    assert -negative_log_likelihood(model, 'euler', half) == pytest.approx(want, rel=1e-10)


def two_state_trace(n: int, seed: int) -> tuple[LinearModel, list]:
    """Return a 2-state, 2-output model and a trace of n steps in three segments."""
    rng = np.random.default_rng(seed)
    model = LinearModel('two', A=np.array([[-0.2, 1.0], [0.0, -0.5]]), C=np.eye(2),
                        Q=np.diag([0.03, 0.2]), R=np.diag([0.5, 2.0]), x0=np.zeros(2),
                        P0=np.eye(2))
    mu = rng.uniform(0.5, 1.5, n)
    ys = rng.standard_normal((n, 2)) * np.exp2(rng.uniform(-10, 10, (n, 1)))
    steps = [StepRecord(m, None if rng.random() < 0.1 else y,
                        variance=float(rng.uniform(0.1, 1.0)) if rng.random() < 0.2 else 0.0)
             for m, y in zip(mu, ys)]
    return model, [steps[:n // 5], steps[n // 5:n // 2], steps[n // 2:]]


def test_the_likelihood_in_blocks_is_the_whole_runs_bit_for_bit(monkeypatch):
    # blocks of 64 innovations (4096 by default): the NIS and log det S summed as np.sum
    # sums the whole columns, so the value is run_trace's to the last bit
    monkeypatch.setattr(noise_fit, 'TRACE_BLOCK', 64)
    model, trace = two_state_trace(3000, 11)
    whole = run_trace(model, 'euler', trace)
    assert whole.count == sum(r.y is not None for seg in trace for r in seg) > 2000
    streamed = trace_log_likelihood(model, 'euler', trace)
    assert np.float64(streamed).tobytes() == np.float64(whole.log_likelihood()).tobytes()
    assert negative_log_likelihood(model, 'euler', trace) == -streamed
    blocks = list(noise_fit.innovation_blocks(model, 'euler', trace, block=64))
    assert max(len(e) for e, _ in blocks) == 64
    np.testing.assert_array_equal(np.concatenate([e for e, _ in blocks]), whole.e)


def step_loop(model, trace):
    """(e_k, S_k) of every measurement step, one `step` at a time (the runs' reference)."""
    es, Ss = [], []
    for segment in trace:
        kf = model.make_filter('euler', allow_nonregressive=True)
        for rec in segment:
            R = None if not rec.variance > 0 else rec.variance * rec.mu
            res = kf.step(rec.mu, rec.y, rec.u, R=R)
            if rec.y is not None:
                es.append(res.innovation)
                Ss.append(res.S)
    return np.array(es), np.array(Ss)


@pytest.mark.parametrize('block', [7, 64, 4096])
def test_the_blocks_made_in_runs_are_the_step_loops(block):
    # runs of measurement steps go through the filter's compiled run, the others (gaps,
    # sample variances, inputs) one step at a time: the same e_k and S_k as a loop of steps
    model, trace = two_state_trace(3000, 12)
    with_input = replace(model, B=np.array([[1.0], [0.5]]))
    rng = np.random.default_rng(3)
    inputs = [[replace(r, u=rng.normal(size=1)) if rng.random() < 0.1 else r for r in seg]
              for seg in trace]
    for m, t in ((model, trace), (with_input, inputs)):
        e, S = step_loop(m, t)
        blocks = list(noise_fit.innovation_blocks(m, 'euler', t, block=block))
        assert max(len(b) for b, _ in blocks) <= block
        np.testing.assert_allclose(np.concatenate([b for b, _ in blocks]), e, rtol=1e-13,
                                   atol=0.0)
        np.testing.assert_allclose(np.concatenate([b for _, b in blocks]), S, rtol=1e-13,
                                   atol=0.0)


def test_a_step_the_run_refuses_raises_as_the_step_does():
    model = LinearModel('one', A=-np.eye(1), C=np.eye(1), Q=np.eye(1), R=np.eye(1),
                        x0=np.zeros(1), P0=np.eye(1))
    # a graininess that is not > 0: the filter refuses that step, in a run as in a loop
    trace = [[StepRecord(0.1, np.ones(1)), StepRecord(-1.0, np.ones(1))]]
    with pytest.raises(FilterError) as in_run:
        list(noise_fit.innovation_blocks(model, 'euler', trace))
    with pytest.raises(FilterError) as in_loop:
        model.make_filter('euler').step(-1.0, np.ones(1))
    assert str(in_run.value) == str(in_loop.value)


def test_the_likelihood_of_the_first_steps_is_that_of_the_trace_cut_there(monkeypatch):
    # steps=K: log L of the first K measurement steps (the coarse search's), bit for bit
    # that of the trace cut after its K-th measurement, across segments and blocks
    monkeypatch.setattr(noise_fit, 'TRACE_BLOCK', 64)
    model, trace = two_state_trace(3000, 13)
    for k in (1, 63, 64, 65, 500, 2000):
        cut, seen = [], 0
        for segment in trace:
            if seen == k:
                break
            kept = []
            for rec in segment:
                if rec.y is not None:
                    if seen == k:
                        break
                    seen += 1
                kept.append(rec)
            cut.append(kept)
        want = trace_log_likelihood(model, 'euler', cut)
        got = trace_log_likelihood(model, 'euler', trace, steps=k)
        assert np.float64(got).tobytes() == np.float64(want).tobytes(), k
        assert negative_log_likelihood(model, 'euler', trace, k) == -got
    whole = trace_log_likelihood(model, 'euler', trace)
    assert trace_log_likelihood(model, 'euler', trace, steps=10 ** 9) == whole
