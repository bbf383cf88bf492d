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

"""plot_bag on a one-axis alignment bag: the figure draws the bag's estimates and truth."""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions
from tskf_ros.tools import plot_bag
from tskf_ros.tools.plot_alignment import alignment_figure, ESTIMATE, truth_kind
from tskf_ros.tools.plot_estimator import POWER
from tskf_ros.tools.plot_rows import stream

BAG = Path(__file__).resolve().parents[2] / 'bags' / 'led_alignment'


def messages(bag: Path, topic: str) -> list:
    """Return the messages of one topic, deserialized one by one."""
    return [deserialize_message(raw.data, message_class(raw.msgtype))
            for raw in BagReader(bag).messages({topic})]


def test_the_figure_draws_the_estimates_the_truth_and_the_intensity():
    truth = messages(BAG, '/alignment/truth')
    names = list(truth[0].name)
    rows = stream(BagReader(BAG), {'/alignment/estimate': ESTIMATE,
                                   '/alignment/truth': truth_kind(names),
                                   '/photodiode': POWER})
    fig = alignment_figure(rows['/alignment/estimate'], 'test', truth=rows['/alignment/truth'],
                           names=names, intensity=rows['/photodiode'])
    try:
        x1, x2, incidence, intensity = fig.axes[:4]
        # written out from the messages: x in V and deg, the truth's radians in deg
        states = [conversions.msg_to_alignment_state(m)
                  for m in messages(BAG, '/alignment/estimate')]
        np.testing.assert_allclose(x1.lines[0].get_ydata(), [s.x[0] for s in states],
                                   rtol=1e-12)
        np.testing.assert_allclose(x2.lines[0].get_ydata(), [s.x[1] for s in states],
                                   rtol=1e-12)
        t = np.array([s.stamp_ns for s in states]) / 1e9
        np.testing.assert_allclose(x1.lines[0].get_xdata(), t - t[0], rtol=0, atol=1e-6)
        angle = np.degrees([m.position[names.index('incidence')] for m in truth])
        np.testing.assert_allclose(incidence.lines[0].get_ydata(), angle, rtol=1e-12)
        volts = [m.illuminance for m in messages(BAG, '/photodiode')]
        np.testing.assert_allclose(intensity.lines[0].get_ydata(), volts, rtol=0, atol=0)
        for ax in fig.axes[:4]:
            assert ax.get_ylabel() and ax.get_legend() is not None
    finally:
        plt.close(fig)


def test_a_truth_whose_joints_change_is_one_line(tmp_path, capsys):
    # the first truth names three joints, a later one two: not plotted, one line
    bag = tmp_path / 'bag'
    with BagWriter(bag) as w:
        for topic in ('/alignment/estimate', '/alignment/truth'):
            w.add_topic(topic, BagReader(BAG).topics[topic].msgtype)
        for raw in BagReader(BAG).messages({'/alignment/estimate'}):
            w.write('/alignment/estimate', raw.log_time_ns, raw.data)
        for k, m in enumerate(messages(BAG, '/alignment/truth')[:5]):
            if k == 3:
                m.name, m.position = m.name[:2], m.position[:2]
            w.write('/alignment/truth', 10 ** 18 + k, serialize_message(m))
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and '2 positions, the first message had 3' in err[0], err
    assert not (tmp_path / 'png' / 'alignment.png').exists()
