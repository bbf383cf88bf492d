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

"""FixedLagSmoother: its output L points back equals the full rts_smooth on the same prefix."""

import numpy as np
import pytest

from tskf_ros.core import FilterError, FixedLagSmoother, rts_smooth, TimeScaleKalmanFilter

MODEL = {'A': np.array([[0.0, 1.0, 0.0], [-0.5, -0.1, 0.2], [0.0, 0.0, -0.3]]),
         'C': np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
         'G': np.array([[0.0], [1.0], [0.5]]), 'Q': np.array([[0.2]]),
         'R': np.diag([0.3, 0.1]), 'B': np.array([[0.0], [1.0], [0.0]]),
         'D': np.array([0.1, 0.0]), 'x0': np.zeros(3), 'P0': np.eye(3)}


def data(K, seed=11):
    """Irregular graininess (with 1e-3 and 30), missing measurements, an input."""
    rng = np.random.default_rng(seed)
    mu = rng.uniform(0.01, 1.0, K)
    mu[[3, 4, 15]] = 1e-3
    mu[[9, 22]] = 30.0
    y = rng.normal(size=(K, 2))
    y[[2, 9, 10, 23]] = np.nan
    return mu, y, rng.normal(size=(K, 1))


def run(lag, kind, K=30):
    """Feed a filter's steps to a FixedLagSmoother; return its outputs and the data."""
    mu, y, u = data(K)
    kf = TimeScaleKalmanFilter(transition=kind, **MODEL)
    smoother = FixedLagSmoother(lag)
    outputs = []
    for k in range(K):
        res = kf.step(mu[k], None if np.isnan(y[k]).all() else y[k], u[k])
        F, _, _ = kf.transition_matrices(mu[k])
        outputs.append(smoother.add(res, F))
        assert len(smoother) == min(k + 1, lag + 1)
    return outputs, smoother, (mu, y, u)


def full(mu, y, u, kind):
    """Return the full smoother over these points."""
    return rts_smooth(MODEL['A'], MODEL['C'], mu, y, u=u, transition=kind,
                      **{k: v for k, v in MODEL.items() if k not in ('A', 'C')})


def close(a, b):
    """Equal to 1e-12 relative to the largest entry of b (at least 1)."""
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1.0, float(np.max(np.abs(b)))))


@pytest.mark.parametrize('kind', ['euler', 'exact'])
@pytest.mark.parametrize('lag', [0, 1, 4, 12])
def test_output_equals_the_full_smoother_on_every_prefix(lag, kind):
    outputs, _, (mu, y, u) = run(lag, kind)
    t = np.concatenate(([0.0], np.cumsum(mu)))
    for k, out in enumerate(outputs):
        if k < lag:
            assert out is None
            continue
        prefix = full(mu[:k + 1], y[:k + 1], u[:k + 1], kind)
        assert out.point == k - lag
        close(out.x, prefix.xs[k - lag])
        close(out.P, prefix.Ps[k - lag])
        # the output lags the newest point by the time of the last L graininesses
        assert out.delay == pytest.approx(t[k] - t[k - lag], rel=0, abs=1e-12 * t[k])


@pytest.mark.parametrize('lag', [0, 3, 40])
def test_flush_gives_the_points_not_yet_output_as_the_full_smoother(lag):
    outputs, smoother, (mu, y, u) = run(lag, 'exact')
    rest = smoother.flush()
    got = [o.point for o in outputs if o is not None] + [o.point for o in rest]
    assert got == list(range(30))
    assert len(rest) == min(lag, 30) and len(smoother) == 0 and smoother.flush() == []
    if rest:
        whole = full(mu, y, u, 'exact')
        close(np.array([o.x for o in rest]), whole.xs[30 - len(rest):])
        close(np.array([o.P for o in rest]), whole.Ps[30 - len(rest):])
        assert rest[-1].delay == 0.0


def test_memory_is_bounded_by_the_lag():
    kf = TimeScaleKalmanFilter(**MODEL)
    smoother = FixedLagSmoother(5)
    for k in range(500):
        out = smoother.add(kf.step(0.1, [0.0, 0.0]), kf.transition_matrices(0.1)[0])
        assert len(smoother) == min(k + 1, 6)
    assert out.point == 494


@pytest.mark.parametrize('lag', [-1, 1.5, True, '3', None])
def test_a_bad_lag_is_refused(lag):
    with pytest.raises(FilterError, match='lag must be a whole number of points >= 0'):
        FixedLagSmoother(lag)


def test_a_bad_jump_or_step_is_refused_and_the_window_is_unchanged():
    kf = TimeScaleKalmanFilter(**MODEL)
    smoother = FixedLagSmoother(2)
    res = kf.step(0.1, [0.0, 0.0])
    smoother.add(res, kf.transition_matrices(0.1)[0])
    with pytest.raises(FilterError, match=r'F must have shape \(3, 3\) to match the step'):
        smoother.add(res, np.eye(2))
    with pytest.raises(FilterError, match='F has non-finite entries'):
        smoother.add(res, np.full((3, 3), np.nan))
    small = TimeScaleKalmanFilter([[0.0]], [[1.0]], Q=1.0, R=1.0, x0=[0.0], P0=[[1.0]])
    with pytest.raises(FilterError, match='the step has 1 states, the window 3'):
        smoother.add(small.step(0.1, [1.0]), [[1.0]])
    assert len(smoother) == 1
