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

"""EstimatorSession.add_many: the same outcomes, counters and history as add() one by one."""

from hostile_streams import GOOD, moves, SETTINGS, stamps_of, values
from hypothesis import given, strategies as st
import numpy as np
from owc_streams import OWC, T0
import pytest

from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, Outcome
from tskf_ros.owc.session.outcome import Run


def outcomes(items):
    """Return add_many's items as one Outcome per sample."""
    out = []
    for item in items:
        out += item.outcomes() if isinstance(item, Run) else [item]
    return out


def same(a: Outcome, b: Outcome) -> None:
    """Assert that two outcomes are equal, bit for bit."""
    assert (a.status, a.reason, a.message) == (b.status, b.reason, b.message)
    assert [(e.kind, e.stamp_ns, e.revised) for e in a.estimates] == \
        [(e.kind, e.stamp_ns, e.revised) for e in b.estimates]
    for e, f in zip(a.estimates, b.estimates):
        np.testing.assert_array_equal(e.x, f.x)
        np.testing.assert_array_equal(e.P, f.P)
    assert [(j.stamp_ns, j.sigma_ns, j.revised) for j in a.jumps] == \
        [(j.stamp_ns, j.sigma_ns, j.revised) for j in b.jumps]


def check_same_as_one_by_one(config, stamps, ys, variances, nows, split=None):
    """Feed the samples both ways (add_many in pieces cut at split); compare everything."""
    one, many = EstimatorSession(config), EstimatorSession(config)
    expected = [one.add(t, y, v, now_ns=now) for t, y, v, now in zip(stamps, ys, variances, nows)]
    arrays = (np.array(stamps, dtype=np.int64), np.array(ys, dtype=float),
              np.array(variances, dtype=float), np.array(nows, dtype=np.int64))
    got = []
    for piece in np.array_split(np.arange(len(stamps)), split or 1):
        got += outcomes(many.add_many(*(a[piece] for a in arrays)))
    assert len(got) == len(expected)
    for a, b in zip(got, expected):
        same(a, b)
    assert many.stats == one.stats
    assert many.gated_in_a_row == one.gated_in_a_row
    assert [(p.stamp_ns, p.y, p.has_input, p.variance) for p in many.points] == \
        [(p.stamp_ns, p.y, p.has_input, p.variance) for p in one.points]
    for p, q in zip(many.points, one.points):
        np.testing.assert_array_equal(p.x, q.x)
        np.testing.assert_array_equal(p.P, q.P)
    np.testing.assert_array_equal(many.kf.x, one.kf.x)
    np.testing.assert_array_equal(many.kf.P, one.kf.P)
    assert many.input.frequency.count == one.input.frequency.count
    assert vars(many.input.stamps) == vars(one.input.stamps)
    assert many.diagnostics() == one.diagnostics()


@pytest.mark.parametrize('transition', ['euler', 'exact'])
@pytest.mark.parametrize('split', [1, 3])
def test_a_1khz_stream_with_jitter_outliers_gaps_and_late_samples(transition, split):
    rng = np.random.default_rng(7)
    n = 600
    stamps = T0 + np.cumsum(rng.choice([1_000_000, 1_000_000, 999_000, 1_002_000, 5_000_000],
                                       size=n))
    ys = GOOD + 10.0 * rng.standard_normal(n)
    ys[rng.choice(n, 12, replace=False)] += 3000.0          # gated
    ys[rng.choice(n, 5, replace=False)] = -1.0              # interruptions
    late = rng.choice(np.arange(5, n), 8, replace=False)
    stamps[late] = stamps[late - 3] + 500_000               # inserted late
    stamps[100:106] = stamps[100]                           # duplicates
    stamps[300] += 120 * NS                                 # a forward jump: restart
    stamps[301:] += 120 * NS
    config = EstimatorConfig(OWC, period=1e-3, transition=transition, gate=5.0,
                             gate_patience=3)
    check_same_as_one_by_one(config, stamps.tolist(), ys.tolist(), [0.0] * n,
                             (stamps + 2_000_000).tolist(), split)


def test_message_variances_and_the_gate_off():
    rng = np.random.default_rng(1)
    n = 200
    stamps = (T0 + np.arange(n) * 10_000_000).tolist()
    ys = (GOOD + rng.standard_normal(n)).tolist()
    variances = rng.choice([0.0, 2.0, 5.0], size=n).tolist()
    for use in (False, True):
        config = EstimatorConfig(OWC, period=1e-2, gate=0.0, use_message_variance=use)
        check_same_as_one_by_one(config, stamps, ys, variances, stamps, 4)


@SETTINGS
@given(st.lists(st.tuples(moves, values, st.sampled_from([0.0, 1.0, -1.0])), min_size=1,
                max_size=40), st.integers(1, 4))
def test_hostile_streams(ops, split):
    stamps = stamps_of([move for move, _, _ in ops])
    ys = [y for _, y, _ in ops]
    variances = [v for _, _, v in ops]
    config = EstimatorConfig(OWC, gate=10.0, gate_patience=2)
    check_same_as_one_by_one(config, stamps, ys, variances, [T0] * len(ops),
                             min(split, len(ops)))
