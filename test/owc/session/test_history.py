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
Late samples: inserted into the time scale and the filter re-run from the left neighbour.

Against the offline run of the core filter over the full time scale, and against the same
samples delivered in order (Hypothesis); the history outside the rewind is untouched.
"""

from hostile_streams import GOOD, SETTINGS
from hypothesis import given, strategies as st
import numpy as np
from owc_streams import collect, feed, feed_seconds, measurements, OWC, owc_session, power
from owc_streams import STAMPS, T0, THETA
import pytest

from tskf_ros.core.linear_models import owc, run_filter
from tskf_ros.core.time_scales import discrete
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession


def test_late_sample_is_inserted_and_rerun_equals_offline():
    model = owc()
    y = measurements(model, STAMPS)
    order = list(range(STAMPS.size))
    order.remove(8)
    order.insert(11, 8)                # t = 11 arrives after t = 16.25
    session = EstimatorSession(EstimatorConfig(model))
    out = feed(session, STAMPS[order], y[order])
    assert out[11].status == 'inserted'
    ref = run_filter(model, discrete(STAMPS), y)
    # revised estimates: from the left neighbour t = 10 up to the newest point 16.25
    t, x, _ = collect([out[11]], 'corrected', revised=True)
    np.testing.assert_array_equal(t, [10, 11, 12, 16])
    np.testing.assert_allclose(x, ref.x_corr[7:11], rtol=0, atol=1e-9)
    t, x, _ = collect([out[11]], 'predicted', revised=True)
    np.testing.assert_array_equal(t, [11, 12, 16, 16.25])
    np.testing.assert_allclose(x, ref.x_pred[8:12], rtol=0, atol=1e-9)
    # everything after the insertion equals the offline run on the full time scale
    t, x, _ = collect(out[12:], 'corrected')
    np.testing.assert_allclose(x, ref.x_corr[11:-1], rtol=0, atol=1e-9)
    # the main stream never repeats a stamp
    for kind in ('predicted', 'corrected'):
        t, _, _ = collect(out, kind)
        assert np.all(np.diff(t) > 0)
    assert session.stats.inserted == 1


def test_too_old_and_clock_jumps():
    cfg = EstimatorConfig(owc(), history_window=5.0, max_backward=20.0, max_jump=30.0)
    session = EstimatorSession(cfg)
    feed(session, np.arange(1.0, 13.0), np.full(12, 200.0))
    assert session.add(3 * NS, 200.0).reason == 'too_old'           # 9 s late > 5 s
    out = session.add(100 * NS, 200.0)                               # 88 s ahead
    assert out.status == 'reset' and out.reason == 'forward_jump'
    assert [e.kind for e in out.estimates] == ['predicted']
    np.testing.assert_array_equal(out.estimates[0].x, owc().x0)
    out = session.add(50 * NS, 200.0)                                # 50 s back
    assert out.status == 'reset' and out.reason == 'backward_jump'
    assert session.stats.resets['forward_jump'] == 1
    assert session.stats.resets['backward_jump'] == 1


def latest_estimates(outs):
    """(kind, stamp) -> (x, P) of the last estimate published for it (revisions win)."""
    latest = {}
    for out in outs:
        for e in out.estimates:
            latest[(e.kind, e.stamp_ns)] = (e.x, e.P)
    return latest


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 6), st.floats(-50.0, 50.0)), min_size=2,
                max_size=40),
       st.sampled_from(['euler', 'exact']), st.sampled_from([0.5, 1.0]))
def test_late_samples_end_where_the_same_samples_in_order_end(samples, transition, spacing):
    # each sample (after the first) may arrive up to 6 places late; the late-sample
    # re-run (only the tail after the insertion point) must give every stamp the same
    # final estimate as in-order delivery, and the same filter state at the end
    config = EstimatorConfig(OWC, transition=transition, gate=0.0, history_window=10.0)
    stamps = [T0 + int(k * spacing * NS) for k in range(len(samples))]
    values = [GOOD + v for _, v in samples]
    order = sorted(range(len(samples)), key=lambda k: k + (samples[k][0] if k else 0))
    in_order, late = EstimatorSession(config), EstimatorSession(config)
    want = latest_estimates([in_order.add(stamps[k], values[k]) for k in range(len(stamps))])
    outs = [late.add(stamps[k], values[k]) for k in order]
    assert all(o.status in ('accepted', 'inserted') for o in outs), [o.reason for o in outs]
    got = latest_estimates(outs)
    assert got.keys() == want.keys()
    for key, (x, P) in want.items():
        np.testing.assert_allclose(got[key][0], x, rtol=1e-9, err_msg=str(key))
        np.testing.assert_allclose(got[key][1], P, rtol=1e-9, err_msg=str(key))
    np.testing.assert_allclose(late.kf.x, in_order.kf.x, rtol=1e-9)
    np.testing.assert_allclose(late.kf.P, in_order.kf.P, rtol=1e-9)
    assert [p.stamp_ns for p in late.points] == [p.stamp_ns for p in in_order.points]
    assert late.stats.inserted == sum(1 for o in outs if o.status == 'inserted')


def test_a_late_sample_leaves_the_older_history_untouched():
    # O(lateness): the points before the insertion are neither copied nor re-run
    session = EstimatorSession(EstimatorConfig(OWC, period=0.001, history_size=1000,
                                               history_window=1e3, max_backward=1e3))
    stamps = [T0 + k * 1_000_000 for k in range(600)]
    for stamp in stamps:
        session.add(stamp, GOOD)
    before = list(session.points)
    out = session.add(stamps[-3] + 500_000, GOOD)           # between the 3rd and 2nd last
    assert out.status == 'inserted'
    after = list(session.points)
    assert len(after) == len(before) + 1
    assert all(a is b for a, b in zip(after[:-4], before[:-3]))
    # revised: the new point's corrected estimate and predictor, and the two after it
    assert [(e.kind, e.stamp_ns) for e in out.estimates if e.kind == 'predicted'] == [
        ('predicted', p.stamp_ns) for p in after[-3:]]


def test_revisions_come_in_stamp_order_and_a_later_one_supersedes():
    s = owc_session()
    feed_seconds(s, [0, 1, 2, 4, 5, 7, 8])
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
