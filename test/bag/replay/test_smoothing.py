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

"""replay_offline --smooth: the RTS estimates of a replayed stream, per segment, arrays and bag."""

import dataclasses

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from tskf_ros.bag.message_types import typestore
from tskf_ros.bag.replay.cli import main
from tskf_ros.bag.replay.loop import replay_arrays
from tskf_ros.bag.replay.sinks import SMOOTHED_TOPIC
from tskf_ros.core.smoother import rts_smooth
from tskf_ros.messages.estimator_interface import load_config

from ..helpers import BAGS, CONFIG, make_bag, NS

CAI = BAGS / 'owc_cai_td_1hz'
PARAMS = CONFIG / 'owc_estimator.yaml'
KEY = SMOOTHED_TOPIC.lstrip('/')


def reference(arrays, config):
    """rts_smooth called directly on each segment's points (all but the newest of each)."""
    model = config.session.model
    status = arrays['sample.status']
    stamps, values = arrays['sample.stamp_ns'], arrays['sample.value']
    segments, current = [], []
    for t, y, s in zip(stamps.tolist(), values.tolist(), status.tolist()):
        if s == 'reset':
            segments.append(current)
            current = []
        if s in ('accepted', 'reset'):
            current.append((t, y))
        else:
            assert s in ('gap', 'rejected'), s      # no late inserts in these bags
    segments.append(current)
    ts, xs, Ps = [], [], []
    for seg in segments:
        if len(seg) < 2:
            continue
        t = np.array([p[0] for p in seg])
        mu = np.diff(t) / NS
        y = np.array([p[1] for p in seg[:-1]])
        got = rts_smooth(model.A, model.C, mu, y, Q=model.Q, R=model.R, G=model.G,
                         D=model.D, x0=model.x0, P0=model.P0,
                         transition=config.session.transition)
        ts.append(t[:-1])
        xs.append(got.xs)
        Ps.append(got.Ps)
    return np.concatenate(ts), np.concatenate(xs), np.concatenate(Ps)


def test_smoothed_arrays_equal_rts_smooth_on_the_sample_bag(tmp_path):
    config = load_config(PARAMS)
    arrays = replay_arrays(CAI, config, smooth=True)
    t, x, P = reference(arrays, config)
    np.testing.assert_array_equal(arrays[f'{KEY}.stamp_ns'], t)
    np.testing.assert_allclose(arrays[f'{KEY}.x'], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(arrays[f'{KEY}.P'], P, rtol=0, atol=1e-9)
    # the newest stepped point: x(T|T) is the filter's corrected estimate there
    corrected = arrays['estimate/corrected.x']
    assert arrays[f'{KEY}.x'][-1] == pytest.approx(corrected[-1], abs=1e-12)
    # smoothing uses later data: its variance is never above the filter's
    assert (arrays[f'{KEY}.P'][:, 0, 0]
            <= arrays['estimate/corrected.P'][:, 0, 0] + 1e-12).all()


def test_each_segment_between_resets_is_smoothed_on_its_own(tmp_path):
    # a 70 s jump (> max_jump 60 s) re-initialises the session: two segments
    bag = make_bag(tmp_path / 'two', [*range(30), *range(100, 130)])
    config = load_config(PARAMS)
    arrays = replay_arrays(bag, config, smooth=True)
    assert (arrays['sample.status'] == 'reset').sum() == 1
    t, x, P = reference(arrays, config)
    np.testing.assert_array_equal(arrays[f'{KEY}.stamp_ns'], t)
    np.testing.assert_allclose(arrays[f'{KEY}.x'], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(arrays[f'{KEY}.P'], P, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(arrays[f'{KEY}.segment'], [0] * 29 + [1] * 29)


def test_cli_smooth_writes_the_topic_and_npz(tmp_path, capsys):
    out = tmp_path / 'smoothed'
    assert main([str(CAI), str(out), '--smooth', '--params-file', str(PARAMS), '-q']) == 0
    npz = tmp_path / 'a.npz'
    assert main([str(CAI), '--npz', str(npz), '--smooth', '--params-file', str(PARAMS),
                 '-q']) == 0
    arrays = dict(np.load(npz))
    store = typestore()
    with Reader(out) as reader:
        conns = [c for c in reader.connections if c.topic == SMOOTHED_TOPIC]
        assert [c.msgtype for c in conns] == ['std_msgs/msg/Float64MultiArray']
        msgs = [store.deserialize_cdr(raw, conns[0].msgtype)
                for _, _, raw in reader.messages(connections=conns)]
    # the estimate layout: data = [sec, nanosec, mu, x, P], dim[0].label the kind
    assert {m.layout.dim[0].label for m in msgs} == {'smoothed'}
    stamps = [int(m.data[0]) * NS + int(m.data[1]) for m in msgs]
    np.testing.assert_array_equal(stamps, arrays[f'{KEY}.stamp_ns'])
    np.testing.assert_allclose([m.data[3] for m in msgs],
                               arrays[f'{KEY}.x'][:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose([m.data[4] for m in msgs],
                               arrays[f'{KEY}.P'][:, 0, 0], rtol=0, atol=1e-12)
    # mu: the step from each point to the next of its segment
    mus = np.array([m.data[2] for m in msgs])
    same = np.diff(arrays[f'{KEY}.segment']) == 0
    np.testing.assert_allclose(mus[:-1][same], np.diff(stamps)[same] / NS, rtol=1e-12)


def test_without_smooth_nothing_changes(tmp_path):
    config = load_config(PARAMS)
    plain = replay_arrays(CAI, config)
    smoothed = replay_arrays(CAI, config, smooth=True)
    assert not any(k.startswith(KEY) for k in plain)
    columns = ('stamp_ns', 'x', 'P', 'segment')
    assert set(smoothed) - set(plain) == {f'{KEY}.{c}' for c in columns}
    for k, v in plain.items():
        np.testing.assert_array_equal(smoothed[k], v, err_msg=k)
    out = tmp_path / 'plain'
    assert main([str(CAI), str(out), '--params-file', str(PARAMS), '-q']) == 0
    with Reader(out) as reader:
        assert SMOOTHED_TOPIC not in {c.topic for c in reader.connections}


def test_smooth_with_the_alignment_filter_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main([str(BAGS / 'led_alignment'), str(tmp_path / 'a'), '--filter', 'alignment',
              '--smooth'])
    assert exc.value.code == 2
    assert '--smooth' in capsys.readouterr().err


class DictRecorder:
    """The definition: every estimate and jump by stamp (the newest kept), RTS in numpy."""

    def __init__(self, config):
        self.kf = config.model.make_filter(config.transition)
        self.segments = [({}, {}, {})]

    def outcome(self, out):
        if out.status == 'reset' and self.segments[-1][0]:
            self.segments.append(({}, {}, {}))
        if out.status not in ('accepted', 'inserted', 'reset'):
            return
        predicted, corrected, sigma = self.segments[-1]
        for e in out.estimates:
            (predicted if e.kind == 'predicted' else corrected)[e.stamp_ns] = (e.x, e.P)
        for j in out.jumps:
            sigma[j.stamp_ns] = j.sigma_ns

    def smoothed(self):
        ts, xs, Ps = [], [], []
        for predicted, corrected, sigma in self.segments:
            stamps = sorted(sigma)
            x, P = [None] * len(stamps), [None] * len(stamps)
            for k in range(len(stamps) - 1, -1, -1):
                t = stamps[k]
                x_f, P_f = corrected.get(t) or predicted[t]
                if k == len(stamps) - 1:
                    x[k], P[k] = x_f, P_f
                    continue
                x_p, P_p = predicted[sigma[t]]
                F = self.kf.transition_matrices((sigma[t] - t) / NS)[0]
                # G = P(t|t) F^T P(sigma|t)^-1; x(t|T), P(t|T) (Rauch, Tung & Striebel 1965)
                G = P_f @ F.T @ np.linalg.inv(P_p)
                x[k] = x_f + G @ (x[k + 1] - x_p)
                P[k] = P_f + G @ (P[k + 1] - P_p) @ G.T
            ts += stamps
            xs += x
            Ps += P
        return np.array(ts), np.array(xs), np.array(Ps)


@pytest.mark.parametrize('name', ['reference_estimator', 'owc_estimator'])
def test_rows_made_final_in_chunks_are_the_estimates_kept_by_stamp(monkeypatch, name):
    # 3000 samples at 1 kHz, every 13th pair swapped (the second arrives late: inserted,
    # the filter re-run from its left neighbour) and a reset in the middle; a history of
    # 3 points and chunks of 8 make all but the newest points final rows early: the same
    # numbers as the recorder that keeps everything by stamp (the same bits), and as the
    # definition (RTS written out in numpy)
    from tskf_ros.bag.replay import rts_replay
    from tskf_ros.owc.innovation_trace import Measurement, run_stream
    config = dataclasses.replace(load_config(CONFIG / f'{name}.yaml').session, history_size=3)
    rng = np.random.default_rng(2)
    stamps = (1_700_000_000 * NS + np.cumsum(rng.integers(990_000, 1_010_000, 3000))
              + np.where(np.arange(3000) >= 1500, 70 * NS, 0)).tolist()
    for i in range(0, 2999, 13):
        stamps[i], stamps[i + 1] = stamps[i + 1], stamps[i]
    events = [Measurement(t, 1.0 + 0.1 * np.sin(i / 40) + 0.01 * rng.standard_normal(), 0.0,
                          max(stamps[:i + 1]) + 50_000) for i, t in enumerate(stamps)]
    kept = rts_replay.SmoothingRecorder(config)
    monkeypatch.setattr(rts_replay, 'CHUNK', 8)
    chunked = rts_replay.SmoothingRecorder(config)
    assert chunked.live == 4 * 3 + 8
    definition = DictRecorder(config)
    statuses = []

    def observe(out):
        statuses.append(out.status)
        for recorder in (kept, chunked, definition):
            recorder.outcome(out)
    kept.live = 10**9                       # never made final before the end
    run_stream(config, events, use_now=True, observe=observe)
    assert statuses.count('inserted') > 100 and statuses.count('reset') == 1
    # the first segment made final at the reset; the second's oldest points as they age
    assert len(chunked.segments) == 2 and len(kept.segments) == 2
    assert kept.rows.count == 1498 and chunked.rows.count > 1498 + 1400
    got, sigma = chunked.smoothed_rows()
    want = kept.smoothed()
    for field in got._fields:
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
    t, x, P = definition.smoothed()
    np.testing.assert_array_equal(got.stamp_ns, t)
    np.testing.assert_allclose(got.x, x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.P, P, rtol=0, atol=1e-9)
    # sigma: the next point of the segment
    same = np.diff(got.segment) == 0
    np.testing.assert_array_equal(sigma[:-1][same], got.stamp_ns[1:][same])
    assert chunked.smoothed() is got       # made once (its rows are freed), then kept
