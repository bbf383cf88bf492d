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

"""plot_rows: messages streamed into rows of floats, long series drawn as their envelope."""

from bag.helpers import BAGS
import numpy as np
import pytest
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.cli import main as replay_main
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import BAG_OUTPUT_TOPICS
from tskf_ros.tools.plot_estimator import ESTIMATE
from tskf_ros.tools.plot_rows import band, DRAWN, envelope, stream


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
    got = stream(BagReader(out), {corrected: ESTIMATE})[corrected]
    # the same messages decoded one by one, as the plot did before it streamed
    want = []
    for raw in BagReader(out).messages({corrected}):
        e = conversions.msg_to_state_estimate(deserialize_message(raw.data,
                                                                  message_class(raw.msgtype)))
        want.append([e.stamp_ns / 1e9, e.x[0], e.P[0, 0], e.mu])
    assert got.shape == (len(want), 4) and len(want) > 10
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
