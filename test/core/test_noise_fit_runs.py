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
innovation_blocks' compiled runs against a loop of `step`, property-based.

Random models and traces with gaps, per-sample variances, inputs, extreme
graininesses (1e-9 s, 600 s), huge values (1e308) and steps the filter refuses.  The
blocks must hold the same e_k and S_k (to 1e-12) or raise the same FilterError.
"""

import warnings

from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
import numpy as np

from tskf_ros.core import noise_fit
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.noise_fit import StepRecord
from tskf_ros.core.timescale_kalman import FilterError


def step_loop(model, transition, segments):
    """Return (e, S) of every measurement step, or the FilterError: one `step` at a time."""
    es, Ss = [], []
    try:
        for segment in segments:
            kf = model.make_filter(transition, allow_nonregressive=True)
            for rec in segment:
                own = rec.y is not None and rec.variance > 0
                res = kf.step(rec.mu, rec.y, rec.u,
                              R=np.eye(kf.p) * rec.variance * rec.mu if own else None)
                if rec.y is not None:
                    es.append(np.array(res.innovation))
                    Ss.append(np.array(res.S))
    except FilterError as exc:
        return es, Ss, exc
    return es, Ss, None


def in_blocks(model, transition, segments, block):
    es, Ss = [], []
    try:
        for e, S in noise_fit.innovation_blocks(model, transition, segments, block=block):
            es.extend(e)
            Ss.extend(S)
    except FilterError as exc:
        return es, Ss, exc
    return es, Ss, None


MUS = st.one_of(st.sampled_from([1e-9, 1e-6, 1e-3, 0.01, 0.1, 1.0, 60.0, 600.0]),
                st.floats(1e-9, 600.0), st.floats(0.009, 0.011))
PLAIN_MUS = st.one_of(st.sampled_from([0.01, 0.1, 1.0]), st.floats(0.009, 0.011))
BAD_MUS = st.sampled_from([0.0, -1.0, float('nan'), float('inf')])
VALUES = st.one_of(st.floats(-10.0, 10.0), st.sampled_from([1e308, -1e308, 1e154, 0.0]))
BAD_VALUES = st.sampled_from([float('nan'), float('inf')])


@st.composite
def cases(draw, extreme=True):
    n, p = draw(st.sampled_from([(1, 1), (2, 1), (2, 2), (3, 2)]))
    m = draw(st.sampled_from([0, 1]))
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n)) * 0.5 / np.sqrt(n) - 0.3 * np.eye(n)
    if draw(st.booleans()) and n > 1:
        A = A * 1e3             # fast dynamics: huge mu A at 600 s
    Mq, Mr, M0 = rng.normal(size=(n, n)), rng.normal(size=(p, p)), rng.normal(size=(n, n))
    scale = draw(st.sampled_from([1.0, 1e-12, 1e12]))
    model = LinearModel('hostile', A=A, C=rng.normal(size=(p, n)),
                        Q=(Mq @ Mq.T + 0.1 * np.eye(n)) * scale,
                        R=(Mr @ Mr.T + 0.5 * np.eye(p)) * scale,
                        B=rng.normal(size=(n, m)) if m else None, D=rng.normal(size=p),
                        x0=rng.normal(size=n), P0=M0 @ M0.T + np.eye(n))
    segments = []
    for _ in range(draw(st.integers(1, 3))):
        segment = []
        for _ in range(draw(st.integers(0, 25))):
            kind = draw(st.sampled_from(['y'] * 6 + ['gap', 'var', 'u']
                                        + (['bad_mu', 'bad_y'] if extreme else [])))
            mu = draw(BAD_MUS if kind == 'bad_mu' else MUS if extreme else PLAIN_MUS)
            y = np.array([draw(BAD_VALUES if kind == 'bad_y' else VALUES if extreme
                               else st.floats(-10.0, 10.0)) for _ in range(p)])
            variance = 0.0
            if kind == 'var':
                variance = draw(st.one_of(st.floats(1e-12, 1e6), st.sampled_from(
                    [1e308, float('nan'), -1.0, 0.0])))
            u = np.array([draw(VALUES)]) if kind == 'u' or (m and draw(st.booleans())) \
                else None
            segment.append(StepRecord(mu, None if kind == 'gap' else y, u, variance))
        segments.append(segment)
    transition = draw(st.sampled_from(['euler', 'exact']))
    block = draw(st.sampled_from([1, 2, 3, 7, 4096]))
    return model, transition, segments, block


@settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.one_of(cases(), cases(extreme=False)))
def test_the_runs_are_the_step_loop(case):
    model, transition, segments, block = case
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        want_e, want_S, want_exc = step_loop(model, transition, segments)
        got_e, got_S, got_exc = in_blocks(model, transition, segments, block)
    assert (type(got_exc), str(got_exc)) == (type(want_exc), str(want_exc))
    if want_exc is None:    # blocks yielded before a failure are not all of the steps made
        assert len(got_e) == len(want_e)
        if want_e:
            # the same kernels on the same inputs: equal to 1e-12 relative (inf and NaN
            # where the loop has them)
            np.testing.assert_allclose(np.array(got_e), np.array(want_e), rtol=1e-12, atol=0)
            np.testing.assert_allclose(np.array(got_S), np.array(want_S), rtol=1e-12, atol=0)
