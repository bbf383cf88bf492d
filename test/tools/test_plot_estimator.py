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

"""plot_bag's estimator figure: rows streamed off a bag, long series drawn as envelopes."""

from bag.helpers import BAGS
import matplotlib.pyplot as plt
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.cli import main as replay_main
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import BAG_OUTPUT_TOPICS
from tskf_ros.tools import plot_bag, plot_estimator
from tskf_ros.tools.plot_estimator import band, DRAWN, envelope, estimate_row, stream


def test_a_short_series_is_drawn_as_it_is():
    t = np.arange(10.0)
    y = np.sin(t)
    got = envelope(t, y)
    np.testing.assert_array_equal(got[0], t)
    np.testing.assert_array_equal(got[1], y)


@pytest.mark.parametrize('n', [DRAWN + 1, 3 * DRAWN + 7, 200_003])
def test_a_long_series_is_drawn_as_each_spans_least_and_greatest(n):
    rng = np.random.default_rng(n)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    y = rng.standard_normal(n)
    y[n // 3] = 50.0                      # an excursion of one point stays in sight
    td, yd = envelope(t, y)
    assert td.size == yd.size == DRAWN
    # written out: DRAWN / 2 spans of consecutive points, split as numpy's linspace
    edges = [int(e) for e in np.linspace(0, n, DRAWN // 2 + 1)]
    for i in (0, 1, DRAWN // 4, DRAWN // 2 - 1):
        span = y[edges[i]:edges[i + 1]]
        assert (yd[2 * i], yd[2 * i + 1]) == (span.min(), span.max())
        assert td[2 * i] == td[2 * i + 1] == t[edges[i]]
    assert yd.max() == 50.0 and yd.min() == y.min()
    tb, lo, hi = band(t, y, np.full(n, 0.5))
    assert tb.size == DRAWN // 2
    assert lo.min() == pytest.approx(y.min() - 0.5, abs=1e-12)
    assert hi.max() == pytest.approx(50.5, abs=1e-12)


def test_stream_gives_the_rows_of_each_message(tmp_path):
    out = tmp_path / 'est'
    assert replay_main([str(BAGS / 'owc_cai_td_1hz'), str(out), '-q',
                        '--params-file', str(BAGS.parent / 'config' / 'owc_estimator.yaml')]) == 0
    corrected = BAG_OUTPUT_TOPICS['corrected']
    got = stream(BagReader(out), {corrected: estimate_row})[corrected]
    # the same messages decoded one by one, as the plot did before it streamed
    want = []
    for raw in BagReader(out).messages({corrected}):
        e = conversions.msg_to_state_estimate(deserialize_message(raw.data,
                                                                  message_class(raw.msgtype)))
        want.append([e.stamp_ns / 1e9, e.x[0], e.P[0, 0], e.mu])
    assert got.shape == (len(want), 4) and len(want) > 10
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)


def test_a_long_run_draws_at_most_drawn_points_and_its_rms_over_every_point(monkeypatch):
    n = 5 * DRAWN + 3
    rng = np.random.default_rng(0)
    t = np.arange(n) * 1e-3 + 100.0
    x_true = np.sin(t)
    x = x_true + 0.01 * rng.standard_normal(n)
    rows = np.column_stack([t, x, np.full(n, 1e-4), np.full(n, 1e-3)])
    fig = plot_estimator.estimator_figure(
        {'predictor': rows, 'corrected': rows}, np.column_stack([t, x_true]),
        np.column_stack([t, x_true]), 1.0, 0.0, 'long run')
    try:
        for ax in fig.axes:
            for line in ax.get_lines():
                assert len(line.get_xdata()) <= DRAWN
        labels = [text.get_text() for ax in fig.axes
                  if ax.get_legend() is not None for text in ax.get_legend().get_texts()]
        rms = np.sqrt(np.mean((x - x_true) ** 2))
        assert f'corrected: RMS {rms:.3g} rad' in labels
        assert 'the least and the greatest' in fig.get_suptitle()
    finally:
        plt.close(fig)


def test_an_estimate_topic_that_holds_no_estimate_is_one_line(tmp_path, capsys):
    # a Float64MultiArray of another layout on estimate/corrected: not plotted, one line
    bag = tmp_path / 'bag'
    with BagWriter(bag) as w:
        for topic in (BAG_OUTPUT_TOPICS['predicted'], BAG_OUTPUT_TOPICS['corrected']):
            w.add_topic(topic, 'std_msgs/msg/Float64MultiArray')
        for k in range(3):
            for topic in (BAG_OUTPUT_TOPICS['predicted'], BAG_OUTPUT_TOPICS['corrected']):
                w.write(topic, 10 ** 18 + k, serialize_message(Float64MultiArray(data=[1.0])))
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('plot_bag: error: ') and 'not an estimate' in err[0]
    assert not (tmp_path / 'png' / 'estimator.png').exists()
