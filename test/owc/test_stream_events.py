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

"""EventColumns over more events than a block of its file: the events given back, in order."""

import numpy as np

from tskf_ros.owc.stream_events import EventColumns, Input, Measurement


def test_many_events_of_two_values_come_back_as_given():
    rng = np.random.default_rng(1)
    events: list = []
    for k in range(40_000):
        if k % 7 == 0:
            events.append(Input(k * 1000 - 10, rng.standard_normal(3)))
        events.append(Measurement(k * 1000, rng.standard_normal(2), float(rng.uniform(0, 2)),
                                  None if k % 11 == 0 else k * 1000 + 77))
    cols = EventColumns(2, 3)
    for ev in events:
        cols.append(ev)
    assert cols.measurements == 40_000 and cols.inputs == len(events) - 40_000
    gone = {5000, 31_000_000}
    back = list(cols.events(without=gone))
    kept = [ev for ev in events if isinstance(ev, Input) or ev.stamp_ns not in gone]
    assert len(back) == len(kept)
    for a, b in zip(kept, back):
        assert type(a) is type(b) and a.stamp_ns == b.stamp_ns
        if isinstance(a, Input):
            np.testing.assert_array_equal(a.u, b.u)
        else:
            np.testing.assert_array_equal(a.value, b.value)
            assert (a.variance, a.log_ns) == (b.variance, b.log_ns)
            assert type(b.stamp_ns) is int and type(b.variance) is float
    cols.close()
