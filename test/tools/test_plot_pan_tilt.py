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

"""plot_bag on a two-axis bag: the figure draws the bag's estimates and the true errors."""

from pathlib import Path

import numpy as np
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.writer import BagWriter
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.pan_tilt_messages import msg_to_pan_tilt_state
from tskf_ros.tools import plot_bag
from tskf_ros.tools.plot_estimator import POWER
from tskf_ros.tools.plot_pan_tilt import ESTIMATE, is_pan_tilt_estimate, pan_tilt_figure, TRUTH
from tskf_ros.tools.plot_rows import stream

BAG = Path(__file__).resolve().parents[2] / 'bags' / 'led_pan_tilt'


def read(bag: Path) -> dict:
    """Return {topic: [(log ns, message)]} of the bag, every topic."""
    reader = BagReader(bag)
    out: dict = {}
    for raw in reader.messages(set(reader.topics)):
        msg = deserialize_message(raw.data, message_class(raw.msgtype))
        out.setdefault(raw.topic, []).append((raw.log_time_ns, msg))
    return out


def test_plot_bag_draws_a_two_axis_bag(tmp_path, capsys):
    assert plot_bag.main([str(BAG), '--out', str(tmp_path)]) == 0
    assert 'wrote' in capsys.readouterr().out
    assert (tmp_path / 'alignment.png').stat().st_size > 10_000


def test_the_figure_draws_the_estimates_and_the_true_pointing_error():
    data = read(BAG)
    estimates, truth = data['/pan_tilt/estimate'], data['/pan_tilt/truth']
    rows = stream(BagReader(BAG), {'/pan_tilt/estimate': ESTIMATE, '/pan_tilt/truth': TRUTH,
                                   '/photodiode': POWER})
    fig = pan_tilt_figure(rows['/pan_tilt/estimate'], rows['/pan_tilt/truth'],
                          rows['/photodiode'], 'test')
    x1, pointing, off_axis, intensity = fig.axes[:4]
    # the EKF's lines: the estimates in V and deg, against time from the first estimate
    states = [msg_to_pan_tilt_state(m) for _, m in estimates]
    t = np.array([s.stamp_ns for s in states]) / NS
    # (seconds since 1970 as float64 resolve 0.24 us: the rows and this differ by an ulp)
    np.testing.assert_allclose(x1.lines[0].get_xdata(), t - t[0], rtol=0, atol=1e-6)
    np.testing.assert_allclose(x1.lines[0].get_ydata(), [s.x[0] for s in states], rtol=1e-12)
    np.testing.assert_allclose(pointing.lines[0].get_ydata(), [s.x[1] for s in states],
                               rtol=1e-12)
    # the true error of the boresight, written here from the truth's radians:
    # d_c = wrap(a - a_s) cos e_s, d_e = e - e_s
    pan, tilt, az, el, off = np.degrees(np.array([m.position for _, m in truth])).T
    d_c = ((pan - az + 180.0) % 360.0 - 180.0) * np.cos(np.radians(el))
    np.testing.assert_allclose(pointing.lines[1].get_ydata(), d_c, rtol=0, atol=1e-9)
    np.testing.assert_allclose(pointing.lines[3].get_ydata(), tilt - el, rtol=0, atol=1e-9)
    np.testing.assert_allclose(off_axis.lines[0].get_ydata(), off, rtol=0, atol=1e-9)
    volts = [conversions.msg_to_power(m)[1] for _, m in data['/photodiode']]
    np.testing.assert_allclose(intensity.lines[0].get_ydata(), volts, rtol=0, atol=0)
    for ax in fig.axes[:4]:
        assert ax.get_ylabel() and ax.get_legend() is not None


def test_a_one_axis_estimate_is_not_taken_for_a_two_axis_one():
    one_axis = read(BAG.parent / 'led_alignment')['/alignment/estimate']
    assert not is_pan_tilt_estimate(one_axis[0][1])
    assert is_pan_tilt_estimate(read(BAG)['/pan_tilt/estimate'][0][1])


def test_a_one_axis_estimate_on_the_two_axis_topic_is_one_line(tmp_path, capsys):
    bag = tmp_path / 'bag'
    with BagWriter(bag) as w:
        w.add_topic('/pan_tilt/estimate', 'std_msgs/msg/Float64MultiArray')
        for raw in BagReader(BAG.parent / 'led_alignment').messages({'/alignment/estimate'}):
            w.write('/pan_tilt/estimate', raw.log_time_ns, raw.data)
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'is not a two-axis alignment estimate' in err[0], err
    assert not (tmp_path / 'png' / 'alignment.png').exists()
