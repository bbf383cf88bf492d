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

"""LaggedEstimates on a session's outcomes: x(t_j|t_{j+L}) equals rts_smooth on that prefix."""

from pathlib import Path

import numpy as np
import pytest

from tskf_ros.core import rts_smooth
from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import NS
from tskf_ros.messages.estimator_interface import load_config
from tskf_ros.owc.lagged_estimates import LaggedEstimates
from tskf_ros.owc.session import EstimatorSession

CONFIG = Path(__file__).resolve().parents[2] / 'config'
# 1 Hz with gaps J = 3 (after 4) and J = 4 (after 12), and a dense stretch at 0.25 s
STAMPS = np.array([1, 2, 3, 4, 7, 8, 9, 10, 11, 12, 16, 16.25, 16.5, 16.75, 17, 18, 19, 20])


def measurements(model, t, seed=0):
    """Noisy measurements of a state near x0 at the points t (seeded)."""
    rng = np.random.default_rng(seed)
    x = model.x0 + 0.02 * rng.standard_normal((t.size, model.x0.size))
    y = x @ model.C.T + (0 if model.D is None else model.D)
    return y + np.sqrt(np.diag(model.R)) * rng.standard_normal(y.shape)


def reference(model, stamps, y, last, u=None, transition='euler'):
    """Return the full RTS smoother over the points stamps[:last + 1] (mu: to the next)."""
    mu = np.diff(stamps)[:last + 1]
    return rts_smooth(model.A, model.C, mu, y[:last + 1], Q=model.Q, R=model.R, G=model.G,
                      D=model.D, B=model.B, u=None if u is None else u[:last + 1],
                      x0=model.x0, P0=model.P0, transition=transition)


def run(lag, order, y, config=None):
    """Feed the samples STAMPS[order] to a session; return the smoothed estimates."""
    config = config or load_config(CONFIG / 'owc_estimator.yaml').session
    session, lagged = EstimatorSession(config), LaggedEstimates(lag, config)
    got = []
    for i in order:
        got += lagged.outcome(session.add(int(round(STAMPS[i] * NS)), float(y[i])))
    return got, lagged


@pytest.mark.parametrize('lag', [0, 1, 3, 16])
def test_each_output_is_the_full_smoother_on_its_prefix(lag):
    y = measurements(owc(), STAMPS)[:, 0]
    got, _ = run(lag, range(STAMPS.size), y)
    due = max(STAMPS.size - 1 - lag, 0)
    assert [e.stamp_ns / NS for e in got] == STAMPS[:due].tolist()
    for j, e in enumerate(got):
        xs, Ps = reference(owc(), STAMPS, y, j + lag)
        np.testing.assert_allclose(e.x, xs[j], rtol=0, atol=1e-10)
        np.testing.assert_allclose(e.P, Ps[j], rtol=1e-10, atol=0)
        assert e.mu == STAMPS[j + 1] - STAMPS[j]
        assert e.delay == pytest.approx(STAMPS[j + lag] - STAMPS[j], abs=1e-9)


def test_a_late_sample_behind_what_is_out_gets_no_smoothed_estimate():
    # t = 9 (point 6) late after 16 (point 10), lag 1: t = 10 and 11 were out before it
    y = measurements(owc(), STAMPS)[:, 0]
    order = list(range(6)) + [7, 8, 9, 10, 6] + list(range(11, STAMPS.size))
    got, _ = run(1, order, y)
    stamps = [e.stamp_ns / NS for e in got]
    # the stamps only increase: 9 is left out, nothing is repeated or skipped otherwise
    assert stamps == [t for t in STAMPS[:STAMPS.size - 2] if t != 9]
    # the points after the insertion are smoothed on the revised run
    for e in got:
        k = STAMPS.tolist().index(e.stamp_ns / NS)      # its point, in time order
        if STAMPS[k] >= 12:
            xs, _ = reference(owc(), STAMPS, y, k + 1)
            np.testing.assert_allclose(e.x, xs[k], rtol=0, atol=1e-10)


def test_a_sample_the_session_rejects_changes_nothing():
    y = measurements(owc(), STAMPS)[:, 0]
    config = load_config(CONFIG / 'owc_estimator.yaml').session
    session, lagged = EstimatorSession(config), LaggedEstimates(2, config)
    for t, yi in zip(STAMPS[:6], y[:6]):
        lagged.outcome(session.add(int(t * NS), float(yi)))
    before = list(lagged.steps)
    assert lagged.outcome(session.add(int(STAMPS[3] * NS), 1.0)) == []     # a duplicate
    assert list(lagged.steps) == before


def test_input_only_points_use_the_prediction_into_them():
    # the drogue model: u at every point, a position fix only at some
    config = load_config(CONFIG / 'drogue_estimator.yaml').session
    model = config.model
    rng = np.random.default_rng(3)
    stamps = 1000.0 + 5.0 * np.arange(30)
    u = rng.standard_normal((stamps.size, 1)) * 1e-3
    fixes = {k: rng.standard_normal() for k in (0, 1, 2, 12, 13, 25, 26)}
    session, lagged = EstimatorSession(config), LaggedEstimates(4, config)
    got = []
    for k, t in enumerate(stamps):
        got += lagged.outcome(session.add_input(int(t * NS), u[k]))
        if k in fixes:
            got += lagged.outcome(session.add(int(t * NS), fixes[k]))
    y = np.array([[fixes.get(k, np.nan)] for k in range(stamps.size)])
    assert [e.stamp_ns / NS for e in got] == stamps[:stamps.size - 1 - 4].tolist()
    for j, e in enumerate(got):
        xs, _ = reference(model, stamps, y, j + 4, u, config.transition)
        np.testing.assert_allclose(e.x, xs[j], rtol=0, atol=1e-9)


def test_a_late_sample_after_a_change_of_r_repeats_no_stamp():
    # R changes at run time after t = 12 (the window is flushed), then t = 11.5 arrives
    # late: its re-run must not output again a stamp already out (47.5 after 48 over DDS)
    y = measurements(owc(), STAMPS)[:, 0]
    config = load_config(CONFIG / 'owc_estimator.yaml')
    session, lagged = EstimatorSession(config.session), LaggedEstimates(2, config.session)
    stamps = []
    for t, yi in zip(STAMPS[:10], y[:10]):
        stamps += [e.stamp_ns for e in lagged.outcome(session.add(int(t * NS), float(yi)))]
    model = config.session.model
    new = load_config(CONFIG / 'owc_estimator.yaml',
                      {'R': (4.0 * np.asarray(model.R)).ravel().tolist()}).session
    assert session.reconfigure(new).status == 'accepted'
    stamps += [e.stamp_ns for e in lagged.reconfigure(new)]
    assert stamps[-1] == int(STAMPS[8] * NS)    # the flush: up to the newest step's start
    for t, yi in [(11.5, 0.3)] + list(zip(STAMPS[10:], y[10:])):
        out = session.add(int(t * NS), float(yi))
        stamps += [e.stamp_ns for e in lagged.outcome(out)]
    assert np.all(np.diff(stamps) > 0), np.array(stamps) / NS
    # every point after the flushed ones comes out once, the late one too (lag 2: up to
    # the point two steps before the newest one)
    assert [s / NS for s in stamps if s > STAMPS[8] * NS] == [11.5] + STAMPS[9:-3].tolist()
