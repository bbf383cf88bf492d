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

"""The sinks: the arrays of the analysis mode hold what the output bag holds (rosbags)."""

import numpy as np
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from std_msgs.msg import Float64

from tskf_ros.bag.message_types import typestore
from tskf_ros.bag.replay.cli import main
from tskf_ros.bag.writer import BagWriter

from ..helpers import BAGS, CONFIG, NS


def test_replay_arrays_hold_what_the_output_bag_holds(tmp_path, capsys):
    """The arrays against the output bag decoded by rosbags, field by field."""
    bag = BAGS / 'drogue'
    params = CONFIG / 'drogue_estimator.yaml'
    assert main([str(bag), str(tmp_path / 'est'), '-q', '--params-file', str(params)]) == 0
    assert main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q',
                 '--params-file', str(params)]) == 0
    with np.load(tmp_path / 'a.npz') as f:
        arrays = dict(f)
    store = typestore()
    with Reader(tmp_path / 'est') as reader:
        by_topic = {}
        for conn, t, data in reader.messages():
            by_topic.setdefault(conn.topic, []).append(
                (t, store.deserialize_cdr(data, conn.msgtype)))
    assert {'/estimate/predicted', '/estimate/corrected'} <= set(by_topic)
    revised = by_topic.get('/estimate/revised', [])
    for kind in ('predicted', 'corrected', 'revised/predicted', 'revised/corrected'):
        # the layout: data = [sec, nanosec, mu, x, P], dim[0].label the kind
        rows = [(t, m) for t, m in by_topic.get(f'/estimate/{kind}', revised)
                if m.layout.dim[0].label == kind.split('/')[-1]]
        name = f'estimate/{kind}'
        assert arrays[f'{name}.log_ns'].tolist() == [t for t, _ in rows]
        assert arrays[f'{name}.stamp_ns'].tolist() == [
            int(m.data[0]) * NS + int(m.data[1]) for _, m in rows]
        n = arrays[f'{name}.x'].shape[1]
        for k, (_, m) in enumerate(rows):
            assert m.layout.data_offset == 3 and m.layout.dim[1].size == n
            assert arrays[f'{name}.x'][k].tolist() == m.data[3:3 + n].tolist()
            assert arrays[f'{name}.P'][k].tolist() == m.data[3 + n:].reshape(n, n).tolist()
    # each step t -> sigma(t) is the mu of the prediction into sigma(t) (0: a prior, no step)
    steps = [(int(m.data[0]) * NS + int(m.data[1]), m.data[2])
             for _, m in by_topic['/estimate/predicted'] if m.data[2] > 0]
    assert arrays['estimate/mu.sigma_ns'].tolist() == [sigma for sigma, _ in steps]
    np.testing.assert_allclose(arrays['estimate/mu.mu'], [mu for _, mu in steps], rtol=1e-15)
    diag = by_topic['/diagnostics']
    assert arrays['diagnostics.log_ns'].tolist() == [t for t, _ in diag]
    # per message the worst task, the first at that level

    def level(s):
        return s.level[0] if isinstance(s.level, bytes) else int(s.level)
    worst = [sorted(m.status, key=lambda s: -level(s))[0] for _, m in diag]
    assert arrays['diagnostics.level'].tolist() == [level(s) for s in worst]
    assert arrays['diagnostics.message'].tolist() == [f'{s.name}: {s.message}' for s in worst]
    power = by_topic['/received_power']
    assert arrays['sample.value'].tolist() == [m.illuminance for _, m in power]
    assert set(arrays['sample.status'].tolist()) <= {'accepted', 'inserted', 'gap',
                                                     'rejected', 'reset'}
    assert len(arrays['input.log_ns']) == len(by_topic['/input'])
    assert str(arrays['meta.damage']) == ''
    capsys.readouterr()
    assert main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q']) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'exists already' in err


def test_far_future_log_times_replay_but_diagnostics_past_2038_are_refused(tmp_path, capsys):
    """A bag logged in 2200 (int64 ns holds it; a ROS 2 stamp's int32 seconds do not)."""
    t0 = 7_258_118_400 * NS         # 2200-01-01T00:00:00Z
    times = [t0 + k * 1_000_000 for k in range(2500)]       # 2.5 s at 1 kHz
    with BagWriter(tmp_path / 'bag') as w:
        w.add_topic('/received_power', 'std_msgs/msg/Float64')
        for k, t in enumerate(times):
            w.write('/received_power', t, serialize_message(Float64(data=300.0 + k % 3)))
    (tmp_path / 'p.yaml').write_text('/**:\n  ros__parameters:\n    period: 0.001\n')
    bag, args = str(tmp_path / 'bag'), ['--params-file', str(tmp_path / 'p.yaml'), '-q']
    assert main([bag, str(tmp_path / 'out'), *args]) == 1
    err = [line for line in capsys.readouterr().err.splitlines()
           if not line.startswith('replay_offline: WARNING: std_msgs/msg/Float64 has no header')]
    assert len(err) == 1 and err[0].startswith('replay_offline: error: ')
    err = err[0]
    assert '/diagnostics at 2200-01-01T00:00:01Z: past 2038-01-19T03:14:07Z' in err
    assert '--no-diagnostics' in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'p.yaml']    # nothing left
    # without /diagnostics the bag is written: the inputs copied at their int64 log times,
    # every sample rejected as the node rejects a stamp past 2038 (stamp_range)
    assert main([bag, str(tmp_path / 'out'), *args, '--no-diagnostics']) == 0
    with Reader(tmp_path / 'out') as r:
        logged = [t for c, t, _ in r.messages() if c.topic == '/received_power']
        assert r.topics.keys() >= {'/received_power', '/estimate/corrected'}
    assert logged == times
    # the arrays hold every int64 stamp, and the reason of each rejection
    assert main([bag, *args, '--npz', str(tmp_path / 'a.npz')]) == 0
    with np.load(tmp_path / 'a.npz') as f:
        assert f['sample.stamp_ns'].tolist() == times
        assert set(f['sample.reason'].tolist()) == {'stamp_range'}
        assert f['diagnostics.log_ns'][0] == t0 + NS
