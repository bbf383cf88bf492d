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

"""run_stream's trace, innovations and estimates in bounded memory: the same as kept whole."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from tskf_ros.core.units import NS
from tskf_ros.messages.estimator_interface import load_config
from tskf_ros.owc import innovation_trace
from tskf_ros.owc.innovation_trace import (EventColumns, fit_stream, Input, Measurement,
                                           run_stream, without)

CONFIG = Path(__file__).resolve().parents[2] / 'config'


def late_stream(n: int, seed: int, inputs: bool) -> list:
    """
    Return n samples at 1 Hz with late ones, a reset, and (inputs) inputs.

    Every 13th pair is swapped (the second late: inserted), the stamps jump by 7000 s at
    n / 2 (a reset), and with inputs an input comes before every 5th sample.
    """
    rng = np.random.default_rng(seed)
    stamps = (1_700_000_000 * NS + np.cumsum(rng.integers(990_000_000, 1_010_000_000, n))
              + np.where(np.arange(n) >= n // 2, 7000 * NS, 0)).tolist()
    for i in range(0, n - 1, 13):
        stamps[i], stamps[i + 1] = stamps[i + 1], stamps[i]
    events: list = []
    for i, t in enumerate(stamps):
        if inputs and i % 5 == 0:
            events.append(Input(t - 100_000_000, [0.01 * rng.standard_normal()]))
        events.append(Measurement(t, 1.0 + 0.1 * np.sin(i / 40) + rng.standard_normal(),
                                  0.0, max(stamps[:i + 1]) + 50_000))
    return events


@pytest.mark.parametrize('name, inputs', [('owc_estimator', False), ('drogue_estimator', True)])
def test_final_points_in_columns_are_the_points_kept_whole(monkeypatch, name, inputs):
    # a history of 3 points and chunks of 8 make all but the newest points final early:
    # the same trace, innovations and estimates, bit for bit, as with nothing made final
    # before the end (the collector keeping every point by stamp, sorted at the end)
    config = dataclasses.replace(load_config(CONFIG / f'{name}.yaml').session, history_size=3)
    events = late_stream(1500, 3, inputs)
    whole = run_stream(config, events, use_now=True, estimates=True)
    monkeypatch.setattr(innovation_trace, 'FINAL_AT_ONCE', 8)
    statuses = []
    chunked = run_stream(config, events, use_now=True, estimates=True,
                         observe=lambda out: statuses.append(out.status))
    assert statuses.count('inserted') > 50 and statuses.count('reset') >= 1
    assert len(whole.segments) == len(chunked.segments) >= 2
    assert whole.steps == chunked.steps == sum(len(s) for s in chunked.segments) > 1000
    # without the trace kept, the same count of steps
    assert run_stream(config, events, use_now=True, trace=False).steps == whole.steps
    for seg_a, seg_b in zip(whole.segments, chunked.segments):
        assert len(seg_a) == len(seg_b)
        for a, b in zip(seg_a, seg_b):
            assert a.mu == b.mu and a.variance == b.variance
            for x, y in ((a.y, b.y), (a.u, b.u)):
                assert (x is None) == (y is None)
                if x is not None:
                    np.testing.assert_array_equal(x, y)
    if inputs:
        assert any(rec.u is not None for seg in chunked.segments for rec in seg)
        assert any(rec.y is None for seg in chunked.segments for rec in seg)
    for field in ('e', 'S', 'nis', 'log_det_S'):
        np.testing.assert_array_equal(getattr(whole.innovations, field),
                                      getattr(chunked.innovations, field), err_msg=field)
    for kind in ('corrected', 'predicted'):
        for a, b in zip(whole.estimates.rows(kind), chunked.estimates.rows(kind)):
            np.testing.assert_array_equal(a, b, err_msg=kind)
    assert whole.gated_stamps == chunked.gated_stamps


def test_a_revision_of_a_final_point_is_refused(monkeypatch):
    # a window smaller than the session's history: a late sample would revise a final point
    config = dataclasses.replace(load_config(CONFIG / 'owc_estimator.yaml').session,
                                 history_size=50)
    monkeypatch.setattr(innovation_trace, 'FINAL_AT_ONCE', 1)
    collector = innovation_trace._Collector(config)
    collector.live = 0
    with pytest.raises(RuntimeError, match='made final'):
        run_stream_with(collector, config, late_stream(200, 4, False))


def run_stream_with(collector, config, events):
    """Feed events to a session with a given collector (as run_stream does)."""
    session = innovation_trace.EstimatorSession(config)
    for ev in events:
        out = session.add(ev.stamp_ns, ev.value, ev.variance)
        collector.outcome(out, y=np.atleast_1d(float(ev.value)), stamp_ns=int(ev.stamp_ns))


def test_event_columns_give_back_the_events():
    events = late_stream(300, 5, True)
    cols = EventColumns(1, 1)
    for ev in events:
        cols.append(ev)
    assert len(cols) == len(events) and cols.measurements == 300 and cols.inputs == 60
    for _ in range(2):          # iterated as often as needed
        back = list(cols)
        assert len(back) == len(events)
        for a, b in zip(events, back):
            assert type(a) is type(b) and a.stamp_ns == b.stamp_ns
            if isinstance(a, Input):
                np.testing.assert_array_equal(a.u, b.u)
            else:
                assert (a.value, a.variance, a.log_ns) == (b.value, b.variance, b.log_ns)
    gone = {events[1].stamp_ns, events[7].stamp_ns}
    assert list(without(cols, gone)) == [ev for ev in list(cols) if ev.stamp_ns not in gone
                                         or isinstance(ev, Input)]
    with pytest.raises(ValueError, match='expected 1'):
        cols.append(Measurement(0, [1.0, 2.0]))


def test_fit_from_columns_is_the_fit_from_a_list():
    config = load_config(CONFIG / 'owc_estimator.yaml').session
    events = late_stream(400, 6, False)
    cols = EventColumns()
    for ev in events:
        cols.append(ev)
    a, b = fit_stream(config, events), fit_stream(config, cols)
    np.testing.assert_array_equal(a.result.theta, b.result.theta)
    assert a.excluded == b.excluded and a.rounds == b.rounds
