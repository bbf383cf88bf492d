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

"""The declared diagnostic tasks: their levels and messages are the ones the code sets."""

import pytest

from tskf_ros.core.diagnostic_status import (FrequencyParams, FrequencyStatus, LEVEL_NAMES,
                                             Status, TimeStampParams, TimeStampStatus)
from tskf_ros.core.units import NS
from tskf_ros.led.alignment_diagnostics import POINTING_LEVELS
from tskf_ros.messages.diagnostic_tasks import (INPUT_FREQUENCY_TASK, POINTING_TASK,
                                                readings_frequency_task,
                                                samples_frequency_task, TIMESTAMP_DELAY_TASK)
from tskf_ros.messages.interface_spec import DiagnosticTask
from tskf_ros.messages.node_interfaces import INTERFACES

# DiagnosticStatus's levels a task may report (STALE is the aggregator's, not a task's)
LEVELS = ('OK', 'WARN', 'ERROR')


def declared(task: DiagnosticTask) -> list[tuple[str, str]]:
    """Return the (level, message) pairs a task declares."""
    return [(row.level, row.message) for row in task.levels]


def reported(stat: Status) -> tuple[str, str]:
    """Return a status's (level name, message)."""
    return LEVEL_NAMES[stat.level], stat.message


def frequency_after(events: int, params: FrequencyParams) -> tuple[str, str]:
    """Return what FrequencyStatus reports for events in its first 1 s window."""
    status = FrequencyStatus(params, now_ns=0)
    for _ in range(events):
        status.tick()
    return reported(status.run(Status('f'), NS))


@pytest.mark.parametrize('task', [INPUT_FREQUENCY_TASK, samples_frequency_task('x'),
                                  readings_frequency_task()], ids=lambda t: t.summary[:30])
def test_a_frequency_task_declares_every_summary_of_frequency_status(task):
    # a 10 Hz target with tolerance 0.5 accepts 5 to 15 events in a 1 s window
    params = FrequencyParams(10.0, 10.0, tolerance=0.5)
    got = [frequency_after(n, params) for n in (0, 4, 16, 10)]
    assert got == declared(task)


def stamps_after(delays_s: list, zero: bool = False) -> tuple[str, str]:
    """Return what TimeStampStatus reports after messages of those delays (and a 0 stamp)."""
    status = TimeStampStatus(TimeStampParams())
    now_ns = 100 * NS
    for delay in delays_s:
        status.tick(now_ns - round(delay * NS), now_ns)
    if zero:
        status.tick(0, now_ns)
    return reported(status.run(Status('t')))


def test_the_timestamp_task_declares_every_summary_of_timestamp_status():
    # acceptable delays: -1 s to 5 s (the updater's defaults, the declared summary's)
    got = [stamps_after([]), stamps_after([-1.5]), stamps_after([5.5]),
           stamps_after([0.1], zero=True), stamps_after([0.1, 4.9, -0.9])]
    assert got == declared(TIMESTAMP_DELAY_TASK)


def declared_keys(task: DiagnosticTask) -> list[str]:
    """Return a task's keys, row after row."""
    return [key for row in task.keys for key in row.keys]


def test_the_standard_tasks_declare_their_keys_one_by_one_in_the_order_they_come():
    # a target frequency (min = max, finite): every FrequencyStatus key is there
    frequency = FrequencyStatus(FrequencyParams(10.0, 10.0, 0.5), now_ns=0)
    keys = [kv.key for kv in frequency.run(Status('f'), NS).values]
    assert keys == declared_keys(INPUT_FREQUENCY_TASK)
    stamps = TimeStampStatus(TimeStampParams())
    keys = [kv.key for kv in stamps.run(Status('t')).values]
    assert keys == declared_keys(TIMESTAMP_DELAY_TASK)
    # one key a row: each key's format and meaning has a row of its own
    assert all(len(row.keys) == 1 for task in (INPUT_FREQUENCY_TASK, TIMESTAMP_DELAY_TASK)
               for row in task.keys)


def test_the_pointing_task_declares_the_level_of_every_supervisor_state():
    by_message = {row.message: row.level for row in POINTING_TASK.levels}
    for state, level in POINTING_LEVELS.items():
        assert by_message[state] == LEVEL_NAMES[level], state


@pytest.mark.parametrize('name', sorted(INTERFACES))
def test_every_task_of_every_node_says_what_it_is_and_its_levels(name):
    for task in INTERFACES[name].diagnostics:
        assert task.summary and task.levels and task.keys, task.name
        assert all(row.level in LEVELS and row.when for row in task.levels), task.name
        assert set(task.level_names()) <= set(LEVELS)
