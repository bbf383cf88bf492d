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

"""The session's diagnostic tasks: input frequency and stamps, filter health, time scale."""

import numpy as np
from owc_streams import feed, owc_session, power, T0, task, THETA

from tskf_ros.core.diagnostic_status import ERROR, OK, WARN
from tskf_ros.core.units import NS
from tskf_ros.owc.session.outcome import REJECT_REASONS, RESET_REASONS

FILTER_HEALTH_KEYS = (
    ['Samples received', 'Messages lost (transport)', 'Samples accepted',
     'Samples inserted late', 'Inputs received', 'Inputs accepted', 'Input in force',
     'Points in history', 'Covariance trace', 'Rejections', 'Resets']
    + [f'Rejected ({r})' for r in REJECT_REASONS] + [f'Resets ({r})' for r in RESET_REASONS])
TIME_SCALE_KEYS = ['Gaps', 'Longest gap J (s)', 'Last gaps J (s)', 'mu current (s)',
                   'mu max (s)', 'Last stamp (s)', 'Transition', 'Intervals seen (periods)',
                   'Intervals seen (count)', 'Interval warnings',
                   'Theorem 2 peak bound (low)', 'Theorem 2 peak bound (high)', 'Covariance']


def test_one_status_per_task_in_order_with_its_keys():
    s = owc_session()
    feed(s, np.array([1.0, 2.0, 3.0]), np.full(3, 200.0))
    statuses = s.diagnostics(now_ns=4 * NS)
    assert [st.name for st in statuses] == ['input frequency', 'timestamp delay',
                                            'filter health', 'time scale']
    assert [k for k, _ in statuses[2].values] == FILTER_HEALTH_KEYS
    assert [k for k, _ in statuses[3].values] == TIME_SCALE_KEYS
    # without the receiver clock (an offline replay's own reports) only the last two
    assert [st.name for st in s.diagnostics()] == ['filter health', 'time scale']


def test_long_gap_warns_once_on_the_time_scale():
    session = owc_session(max_gap=5.0)
    feed(session, np.array([1.0, 2.0, 9.0, 10.0]), np.full(4, 200.0))
    status = task(session, 'time scale')
    assert status.level == WARN and 'max_gap' in status.message
    assert status.as_dict()['Gaps'] == '1' and status.as_dict()['Longest gap J (s)'] == '7.0'
    assert task(session, 'time scale').level == OK


def test_input_frequency_as_frequency_status_around_one_over_period():
    s = owc_session(rate_tolerance=0.5)        # expected_rate 0: 1 / period = 1 Hz
    now = T0
    for k in range(12):                               # 1 Hz: met
        s.add(now - NS // 10, power(THETA), now_ns=now)
        now += NS
    freq, stamps = s.diagnostics(now_ns=now)[:2]
    assert (freq.level, freq.message) == (OK, 'Desired frequency met')
    assert freq.as_dict()['Target frequency (Hz)'] == '1.000000'
    assert freq.as_dict()['Minimum acceptable frequency (Hz)'] == '0.500000'
    assert (stamps.level, stamps.message) == (OK, 'Timestamps are reasonable.')
    for k in range(5):                                # 0.25 Hz over the next 5 updates
        now += 4 * NS
        s.add(now - 2 * NS, power(THETA), now_ns=now)
        freq = s.diagnostics(now_ns=now)[0]
    assert (freq.level, freq.message) == (WARN, 'Frequency too low.')
    for k in range(5):                                # nothing over 5 updates
        now += NS
        freq = s.diagnostics(now_ns=now)[0]
    assert (freq.level, freq.message) == (ERROR, 'No events recorded.')
    fresh = owc_session()
    assert fresh.diagnostics(now_ns=T0)[0].level == ERROR      # never any input


def test_a_rejected_sample_is_still_an_event_and_a_restart_an_error():
    s = owc_session()
    s.add(T0, power(THETA), now_ns=T0)
    s.add(T0, power(THETA), now_ns=T0 + NS)           # a duplicate: rejected, but received
    freq, _, health, _ = s.diagnostics(now_ns=T0 + 2 * NS)
    assert freq.as_dict()['Events in window'] == '2'
    assert health.as_dict()['Rejected (duplicate)'] == '1' and health.level == OK
    s.health_error = 'a non-finite state'
    assert task(s, 'filter health').level == ERROR
    assert task(s, 'filter health').level == OK       # consumed by the update before


def test_a_gap_that_ends_in_a_gate_lockout_is_counted():
    # 10 s at 1 Hz, 600 s of nothing, then readings the gate refuses until it restarts
    s = owc_session(max_jump=1000.0, max_backward=1000.0, gate=3.0, gate_patience=2)
    t = [T0 + k * NS for k in range(10)]
    outs = [s.add(stamp, power(THETA)) for stamp in t]
    after = [t[-1] + 600 * NS + k * NS for k in range(3)]
    outs = [s.add(stamp, 1e6) for stamp in after]
    assert [(o.status, o.reason) for o in outs] == [
        ('rejected', 'gated'), ('rejected', 'gated'), ('reset', 'gate_lockout')]
    values = task(s, 'time scale').as_dict()
    assert values['Gaps'] == '1' and float(values['Longest gap J (s)']) == 602.0


def test_a_gap_that_ends_in_a_forward_jump_is_counted():
    s = owc_session(max_jump=60.0)
    s.add(T0, power(THETA))
    out = s.add(T0 + 600 * NS, power(THETA))
    assert (out.status, out.reason) == ('reset', 'forward_jump')
    values = task(s, 'time scale').as_dict()
    assert values['Gaps'] == '1' and float(values['Longest gap J (s)']) == 600.0
