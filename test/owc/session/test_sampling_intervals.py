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
The gaps and sampling intervals against Fang & de Callafon Section III.

Theorem 2's peak-covariance bounds against the fixed point of its recursion found by plain
iteration (and a closed form); Definitions 2-3 on a model with eigenvalues +-2.
"""

import math

import numpy as np
from owc_streams import feed_seconds, owc_session, power, T0, THETA
import pytest

from tskf_ros.core import irregular
from tskf_ros.core.diagnostic_status import WARN
from tskf_ros.core.linear_models import LinearModel, owc, OWC_SLOPE
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, model_from_flat


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
    values = s.diagnostics()[1].as_dict()
    assert values['Intervals seen (periods)'] == '1 2 3 4'
    assert values['Interval warnings'] == ''
    # Fang's discrete system of one nominal period h (Euler: a = 1 + h, q = h G Q G^T = h)
    # measured with R / h at every sample (Table 3's R_d at mu = h): Theorem 2 for 1 and 4
    a, q, r = 1.0 + period, period, 100.0 / period
    lo = fang_scalar_fixed_point(a, OWC_SLOPE, q, r, 1)
    hi = fang_scalar_fixed_point(a, OWC_SLOPE, q, r, 4)
    assert float(values['Theorem 2 peak bound (low)']) == pytest.approx(lo, rel=1e-9)
    assert float(values['Theorem 2 peak bound (high)']) == pytest.approx(hi, rel=1e-9)
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
    times = s.diagnostics()[1]
    assert times.level == WARN and 'interval(s) 2' in times.message
    assert times.as_dict()['Interval warnings'].startswith('2: degenerate')


def test_a_600_s_gap_with_max_jump_1000_does_not_overflow():
    # before: OverflowError in scalar_fixed_point (a ** (2 * kappa))
    s = owc_session(max_jump=1000.0)
    feed_seconds(s, range(5))
    out = s.add(T0 + 605 * NS, power(THETA))
    # 601 x theta predicted (A = 1, Euler): the true reading fails the gate, no exception
    assert (out.status, out.reason) == ('rejected', 'gated')
    s = owc_session(max_jump=1000.0, gate=0.0)
    feed_seconds(s, range(5))
    assert s.add(T0 + 605 * NS, power(THETA)).status == 'accepted'
    values = s.diagnostics()[1].as_dict()
    # (1 + 1)^1200: no finite bound
    assert float(values['Theorem 2 peak bound (high)']) == math.inf
    assert math.isfinite(float(values['Theorem 2 peak bound (low)']))


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
