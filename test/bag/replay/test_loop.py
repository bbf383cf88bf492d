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

"""The replay loop: outputs bounded by the input, whole or nothing, canonical, both forms."""

import subprocess
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader

from tskf_ros.bag.cdr import serialize
from tskf_ros.bag.message_types import message_class, typestore
from tskf_ros.bag.reader import BagReader, RawMessage
from tskf_ros.bag.replay import adapters
from tskf_ros.bag.replay.cli import main
from tskf_ros.bag.replay.loop import replay, replay_arrays
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions
from tskf_ros.tools import plot_bag

from ..helpers import BAGS, CONFIG, make_bag, mcap_file, NS, scalar_bag, T0, TIMEOUT

PARAMS = CONFIG / 'owc_estimator.yaml'


# -- output bounded by the input, not by the span of the clock ---------------------------

def test_a_log_time_gap_gives_one_diagnostics_message_not_one_per_period(tmp_path):
    # 20 messages, 1e5 s apart in the middle: the live node's 1 s timer would fire 1e5
    # times; the offline replay writes one /diagnostics message at the latest due time
    times = list(range(10)) + [1e5 + k for k in range(10)]
    bag = make_bag(tmp_path / 'gap', times)
    res = replay(bag, tmp_path / 'out')
    assert res.read == 20
    assert res.written['/diagnostics'] == 19
    with Reader(tmp_path / 'out') as r:
        diag = [t for c, t, _ in r.messages() if c.topic == '/diagnostics']
    assert len(diag) == 19
    # t = 1..9 s, then the latest due time at the gap (1e5 s), then 1e5 + 1..9 s
    assert diag == [T0 + k * NS for k in range(1, 10)] + \
        [T0 + int(1e5 + k) * NS for k in range(10)]
    assert (tmp_path / 'out' / 'out.mcap').stat().st_size < 200_000


def test_a_clock_that_jumps_to_the_present_finishes(tmp_path):
    # log times of a few seconds (a clock from boot), then the present: 1.7e9 periods
    times = [1.0, 2.0, 3.0] + [1.7e9 + k for k in range(3)]
    bag = make_bag(tmp_path / 'jump', times, start_ns=0)
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.replay.cli', str(bag),
                           str(tmp_path / 'out'), '-q'], capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr
    with Reader(tmp_path / 'out') as r:
        assert r.topics['/diagnostics'].msgcount == 5
        assert r.topics['/received_power'].msgcount == 6


def test_output_is_never_half_written(tmp_path, monkeypatch):
    bag = scalar_bag(tmp_path / 'bag')

    def explode(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(adapters.OfflineEstimator, 'encoded', explode)
    with pytest.raises(KeyboardInterrupt):
        replay(bag, tmp_path / 'out')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']


def padded_and_canonical_bags(tmp_path):
    """Write the same messages in two bags: rclpy's padded Fast-CDR bytes, canonical ones."""
    bags = {}
    for form, encode in (('padded', serialize_message), ('canonical', serialize)):
        with BagWriter(tmp_path / form) as w:
            w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
            w.add_topic('/true_angle', 'sensor_msgs/msg/JointState')
            for k in range(120):
                stamp = T0 + k * NS // 10
                w.write('/true_angle', stamp, encode(
                    conversions.angle_to_msg(stamp, [0.1 * np.sin(k / 9)], ['theta'])))
                if k % 17 != 5:
                    w.write('/received_power', stamp, encode(
                        conversions.power_to_msg(stamp, 300.0 + 20.0 * np.cos(k / 7), 4.0)))
        bags[form] = tmp_path / form
    return bags


def test_every_reader_takes_both_the_padded_and_the_canonical_form(tmp_path):
    bags = padded_and_canonical_bags(tmp_path)
    raw = {form: list(BagReader(bag).messages()) for form, bag in bags.items()}
    angles = [(a, b) for a, b in zip(raw['padded'], raw['canonical'])
              if a.topic == '/true_angle']
    assert all(len(a.data) == len(b.data) + 8 for a, b in angles)     # the test means it
    with pytest.raises(Exception):     # why the package reads with rclpy, not rosbags
        typestore().deserialize_cdr(angles[0][0].data, 'sensor_msgs/msg/JointState')
    for a, b in zip(raw['padded'], raw['canonical']):       # message_types + rclpy
        cls = message_class(a.msgtype)
        assert deserialize_message(a.data, cls) == deserialize_message(b.data, cls)
    outputs = {}
    for form, bag in bags.items():       # offline replay, in memory, to a bag and to arrays
        res = replay(bag, None, params_file=PARAMS, diagnostics=False)
        outputs[form] = [(t, n, m) for t, n, m in res.outputs if t.startswith('/estimate')]
        assert main([str(bag), str(tmp_path / f'{form}_est'), '-q',
                     '--params-file', str(PARAMS)]) == 0
        arrays = replay_arrays(bag, PARAMS)
        outputs[form + ' arrays'] = arrays['estimate/corrected.x'].tolist()
        assert plot_bag.main([str(bag), '--out', str(tmp_path / f'{form}_png')]) == 0
    assert outputs['padded'] == outputs['canonical'] and outputs['padded']
    assert outputs['padded arrays'] == outputs['canonical arrays']
    est = {form: [m.data for m in BagReader(tmp_path / f'{form}_est').messages()
                  if m.topic.startswith('/estimate')] for form in bags}
    assert est['padded'] == est['canonical']


@pytest.mark.parametrize('bag, params, extra', [
    ('owc_cai_td_1hz', 'owc_estimator.yaml', []),
    ('led_alignment', 'alignment.yaml', ['--filter', 'alignment'])])
def test_a_replayed_bag_is_canonical_and_equals_the_in_memory_replay(tmp_path, bag, params,
                                                                     extra):
    bag, params = BAGS / bag, CONFIG / params
    assert main([str(bag), str(tmp_path / 'est'), '-q', '--params-file', str(params)]
                + extra) == 0
    memory = replay(bag, None, params_file=params,
                    filter='alignment' if extra else 'estimator')
    store = typestore()
    written = list(BagReader(tmp_path / 'est').messages())
    assert [(m.topic, m.log_time_ns) for m in written] == \
        [(t, n) for t, n, _ in memory.outputs]
    for raw, (_, _, msg) in zip(written, memory.outputs):
        store.deserialize_cdr(raw.data, raw.msgtype)        # strict: canonical
        if not isinstance(msg, RawMessage):       # an output, not a copied input
            assert deserialize_message(raw.data, type(msg)) == msg
            assert raw.data == serialize(msg)
    with mcap_file(tmp_path / 'est').open('rb') as f:
        assert sum(1 for _ in make_reader(f, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages()) == len(written)


# -- the session in runs: the same outputs as one sample at a time -----------------------

@pytest.mark.parametrize('bag', ['owc_ge_1khz', 'owc_cai_td_1hz'])
def test_runs_give_the_outputs_of_one_sample_at_a_time(tmp_path, bag, monkeypatch):
    # add_many against add (the live node's path): every array equal, and the bags written
    # the same files byte for byte
    arrays = replay_arrays(BAGS / bag, PARAMS)
    replay(BAGS / bag, tmp_path / 'runs', params_file=PARAMS)
    monkeypatch.setattr(adapters.OfflineEstimator, 'batched', False)
    single = replay_arrays(BAGS / bag, PARAMS)
    replay(BAGS / bag, tmp_path / 'single', params_file=PARAMS)
    assert arrays.keys() == single.keys()
    for key, value in arrays.items():
        np.testing.assert_array_equal(value, single[key], err_msg=key)
    runs, single_bag = (mcap_file(tmp_path / name).read_bytes() for name in ('runs', 'single'))
    assert runs == single_bag


@pytest.mark.parametrize('compress', [False, True])
def test_the_arrays_read_in_blocks_are_the_arrays_read_one_by_one(tmp_path, compress,
                                                                  monkeypatch):
    rng = np.random.default_rng(3)
    path = tmp_path / 'bag'
    with BagWriter(path, compress=compress, chunk_size=3000) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(3000):
            stamp = T0 + k * 1_000_000 + int(rng.integers(-10_000, 10_001))
            msg = conversions.power_to_msg(stamp, 300.0 + rng.normal(0.0, 2.0), 4.0)
            if 1200 <= k < 1300:
                msg.header.frame_id = 'pm' + 'x' * (k % 5)     # lengths differ: one by one
            w.write('/received_power', stamp + 200_000, serialize_message(msg))
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    period: 0.001\n')
    fast = replay_arrays(path, params)
    assert any(not isinstance(i, RawMessage) for i in BagReader(path).message_blocks())
    blocks = BagReader.message_blocks
    monkeypatch.setattr(BagReader, 'message_blocks',     # the per-message path
                        lambda self, topics=None: blocks(self, topics, blocks=False))
    slow = replay_arrays(path, params)
    assert fast.keys() == slow.keys() and len(fast['sample.log_ns']) == 3000
    for key in fast:
        assert fast[key].dtype == slow[key].dtype and np.array_equal(fast[key], slow[key]), key
    assert len(fast['diagnostics.log_ns']) >= 2
