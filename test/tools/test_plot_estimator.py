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

"""plot_bag's estimator figure: a long run drawn as envelopes, a bad estimate in one line."""

import matplotlib.pyplot as plt
import numpy as np
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray

from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages.estimator_interface import BAG_OUTPUT_TOPICS
from tskf_ros.tools import plot_bag, plot_estimator
from tskf_ros.tools.plot_rows import DRAWN


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
