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

"""
FrequencyStatus, TimeStampStatus and mergeSummary key by key against diagnostic_updater.

The expected keys, messages and formats are copied from ros/diagnostics (ros2-jazzy)
diagnostic_updater/_update_functions.py and _diagnostic_status_wrapper.py; the numbers
are worked out by hand from the clock times handed in.
"""

import math

import pytest

from tskf_ros.core.diagnostic_status import (ERROR, expected_frequency, FrequencyParams,
                                             FrequencyStatus, InputStream, OK, Status,
                                             TimeStampParams, TimeStampStatus, WARN)
from tskf_ros.core.units import NS

# FrequencyStatus.run, in the order it adds them ('Target' when min == max, 'Minimum' when
# min > 0, 'Maximum' when max is finite)
FREQUENCY_KEYS = ['Events in window', 'Events since startup', 'Duration of window (s)',
                  'Actual frequency (Hz)', 'Target frequency (Hz)',
                  'Minimum acceptable frequency (Hz)', 'Maximum acceptable frequency (Hz)']
# TimeStampStatus.run (the colons are upstream's)
TIMESTAMP_KEYS = ['Earliest timestamp delay:', 'Latest timestamp delay:',
                  'Earliest acceptable timestamp delay:', 'Latest acceptable timestamp delay:',
                  'Late diagnostic update count:', 'Early diagnostic update count:',
                  'Zero seen diagnostic update count:']
T0 = 1_000 * NS


def run(task: FrequencyStatus, now_ns: int) -> Status:
    return task.run(Status('frequency'), now_ns)


def test_frequency_status_keys_levels_and_window_of_window_size_updates():
    task = FrequencyStatus(FrequencyParams(10.0, 10.0, tolerance=0.1, window_size=2), T0)
    for _ in range(10):
        task.tick()
    s = run(task, T0 + NS)                        # 10 events in 1 s: 10 Hz, met
    assert [k for k, _ in s.values] == FREQUENCY_KEYS
    assert (s.level, s.message) == (OK, 'Desired frequency met')
    assert s.as_dict() == {
        'Events in window': '10', 'Events since startup': '10',
        'Duration of window (s)': '1.000000', 'Actual frequency (Hz)': '10.000000',
        'Target frequency (Hz)': '10.000000',
        'Minimum acceptable frequency (Hz)': '9.000000',
        'Maximum acceptable frequency (Hz)': '11.000000'}
    for _ in range(5):
        task.tick()
    # window_size = 2: the window reaches back two updates, to T0 (15 events in 2 s)
    s = run(task, T0 + 2 * NS)
    assert (s.level, s.message) == (WARN, 'Frequency too low.')
    assert s.as_dict()['Events in window'] == '15'
    assert s.as_dict()['Actual frequency (Hz)'] == '7.500000'
    for _ in range(30):
        task.tick()
    s = run(task, T0 + 3 * NS)                    # from T0 + 1 s: 35 events in 2 s
    assert (s.level, s.message) == (WARN, 'Frequency too high.')
    assert s.as_dict()['Actual frequency (Hz)'] == '17.500000'
    run(task, T0 + 4 * NS)
    s = run(task, T0 + 5 * NS)                    # nothing since T0 + 3 s
    assert (s.level, s.message) == (ERROR, 'No events recorded.')
    assert s.as_dict()['Events since startup'] == '45'


def test_frequency_status_without_target_or_max_has_only_the_keys_upstream_adds():
    task = FrequencyStatus(FrequencyParams(0.0, math.inf), T0)
    task.tick()
    s = run(task, T0 + NS)
    assert [k for k, _ in s.values] == FREQUENCY_KEYS[:4]
    assert s.level == OK
    bounded = FrequencyStatus(FrequencyParams(1.0, 2.0, tolerance=0.0), T0)
    bounded.tick()
    assert [k for k, _ in run(bounded, T0 + NS).values] == (
        FREQUENCY_KEYS[:4] + FREQUENCY_KEYS[5:])


def test_expected_frequency_defaults_to_the_nominal_period():
    assert expected_frequency(0.0, 0.5, 0.01) == FrequencyParams(100.0, 100.0, 0.5)
    assert expected_frequency(20.0, 0.1, 0.01) == FrequencyParams(20.0, 20.0, 0.1)


def test_timestamp_status_keys_levels_and_counts():
    task = TimeStampStatus(TimeStampParams(-1.0, 5.0))
    s = task.run(Status('stamps'))
    assert [k for k, _ in s.values] == TIMESTAMP_KEYS
    assert (s.level, s.message) == (WARN, 'No data since last update.')
    task.tick(T0 - 2 * NS, T0)                    # 2 s late
    task.tick(T0 - NS // 2, T0)                   # 0.5 s late
    s = task.run(Status('stamps'))
    assert (s.level, s.message) == (OK, 'Timestamps are reasonable.')
    assert s.as_dict() == {
        'Earliest timestamp delay:': '0.500000', 'Latest timestamp delay:': '2.000000',
        'Earliest acceptable timestamp delay:': '-1.000000',
        'Latest acceptable timestamp delay:': '5.000000',
        'Late diagnostic update count:': '0', 'Early diagnostic update count:': '0',
        'Zero seen diagnostic update count:': '0'}
    task.tick(T0 - 6 * NS, T0)                    # 6 s late
    s = task.run(Status('stamps'))
    assert (s.level, s.message) == (ERROR, 'Timestamps too far in past seen.')
    task.tick(T0 + 2 * NS, T0)                    # 2 s in the future
    task.tick(0, T0)
    s = task.run(Status('stamps'))
    # the summaries are set in turn: the last that applies wins, as upstream
    assert (s.level, s.message) == (ERROR, 'Zero timestamp seen.')
    assert s.as_dict()['Earliest timestamp delay:'] == '-2.000000'
    assert s.as_dict()['Late diagnostic update count:'] == '1'
    assert s.as_dict()['Early diagnostic update count:'] == '1'
    assert s.as_dict()['Zero seen diagnostic update count:'] == '1'


def test_merge_summary_as_the_status_wrapper():
    s = Status('x')
    s.summary(OK, 'ok')
    s.merge_summary(OK, 'fine')
    assert (s.level, s.message) == (OK, 'ok; fine')
    s.merge_summary(WARN, 'a gap')                 # a non-OK level replaces an OK message
    assert (s.level, s.message) == (WARN, 'a gap')
    s.merge_summary(OK, 'ignored')
    assert (s.level, s.message) == (WARN, 'a gap')
    s.merge_summary(ERROR, 'restarted')
    assert (s.level, s.message) == (ERROR, 'a gap; restarted')


def test_a_new_status_is_an_error_until_a_task_fills_it():
    # as Updater.update builds each task's status before calling it
    assert (Status('x').level, Status('x').message) == (ERROR, 'No message was set')


def test_input_stream_starts_its_window_at_the_first_message():
    stream = InputStream(FrequencyParams(2.0, 2.0, 0.5))
    for k in range(4):
        stream.note(T0 + k * NS // 2 - NS // 10, T0 + k * NS // 2)
    frequency, stamps = stream.run(T0 + 2 * NS)
    assert (frequency.name, stamps.name) == ('input frequency', 'timestamp delay')
    assert frequency.as_dict()['Actual frequency (Hz)'] == '2.000000'
    assert frequency.level == OK
    assert float(stamps.as_dict()['Latest timestamp delay:']) == pytest.approx(0.1)
