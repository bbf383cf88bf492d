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
The power_meter_driver against hostile input: templates, readings, backends, Ctrl-C.

In-process tests use test_power_meter_driver's Loop; the process tests start the driver
as its console script does.  Waits are conditions with deadlines (the Ctrl-C test waits
for the line the hanging meter prints when its query starts).
"""

import os
from pathlib import Path
import selectors
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import pytest
from rclpy.parameter import Parameter

from test_power_meter_driver import Loop, TIMEOUT, values
from visa_faults import bench, HANG_MARK, SIM_YAML

REPO = Path(__file__).resolve().parents[2]
TEST_DIR = REPO / 'test'


@pytest.fixture
def loop(ros_context):
    lp = Loop(ros_context)
    yield lp
    lp.close()


def run_driver(*ros_args, **kwargs):
    return subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.power_meter_driver',
                           '--ros-args', *ros_args], cwd=REPO, env=dict(os.environ),
                          capture_output=True, text=True, timeout=TIMEOUT, **kwargs)


def one_line(result) -> str:
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 1 and len(lines) == 1, result.stderr
    assert 'Traceback' not in result.stderr
    return lines[0]


@pytest.mark.parametrize('template', ['{unit.foo}', '{0[1]}', '{unit[0]}',
                                      '{wavelength.real}'])
def test_a_template_with_attribute_or_index_fields_is_refused_at_run_time(
        loop, tmp_path, template):
    driver = loop.driver(bench(tmp_path))
    loop.until(lambda: len(loop.power) >= 1, 'a reading')
    for name in ('scpi_read', 'scpi_set_unit', 'scpi_identify'):
        result = driver.set_parameters([Parameter(name, value=template)])[0]
        assert not result.successful and 'is not a field' in result.reason, result.reason
        assert driver.get_parameter(name).value != template
    start = len(loop.power)
    loop.until(lambda: len(loop.power) >= start + 2, 'readings go on')


def test_a_template_with_an_attribute_field_in_a_params_file_exits_1_with_one_line(tmp_path):
    params = tmp_path / 'params.yaml'
    params.write_text('/**/power_meter_driver:\n  ros__parameters:\n'
                      '    scpi_read: "{unit.foo}"\n')
    line = one_line(run_driver('-p', f'backend:={SIM_YAML}@sim', '--params-file', str(params)))
    assert line.startswith('power_meter_driver: cannot start: ') and '{unit.foo}' in line


@pytest.mark.parametrize('text', [
    'spec: "1.1"\ndevices: [\n',                    # a parser error
    'spec: "1.1"\n\tdevices: {}\n',                  # a scanner error (tab)
    'spec: "1.1"\ndevices: 5\nresources: 7\n',      # YAML, not a device file
    '- just\n- a list\n',
    '',
])
def test_a_malformed_pyvisa_sim_file_as_backend_exits_1_with_one_line(tmp_path, text):
    bad = tmp_path / 'bad.yaml'
    bad.write_text(text)
    line = one_line(run_driver('-p', f'backend:={bad}@sim'))
    assert line.startswith('power_meter_driver: cannot start: VISA backend'), line
    assert len(line) < 400, line


@pytest.mark.parametrize('unit, reply, reason', [('DBM', '-1E30', 'underflow'),
                                                 ('W', '-0.0', 'negative')])
def test_a_reading_that_is_no_positive_power_is_dropped_counted_and_said_once(
        loop, tmp_path, capfd, unit, reply, reason):
    b = bench(tmp_path)
    driver = loop.driver(b)
    loop.until(lambda: len(loop.power) >= 1, 'a reading')
    b.set_unit(unit)
    b.set_power(reply)
    s = loop.diagnostics_after(lambda s: s.level == DiagnosticStatus.WARN
                               and int(values(s)[f'skipped_{reason}']) >= 3,
                               f'3 readings skipped as {reason}')
    assert reply in values(s)['last_error']
    b.set_unit('W')
    b.set_power('1.5E-03')
    loop.until(lambda: loop.power[-1].illuminance == 1.5, 'the next valid reading')
    assert all(m.illuminance > 0 for m in loop.power)        # no 0.0, no -0.0
    assert driver.session.skipped[reason] >= 3
    said = [line for line in capfd.readouterr().err.splitlines()
            if f'skipped_{reason}' in line]
    assert len(said) == 1 and f'{reply!r}' in said[0], said


def lines_until(proc, mark: str, deadline: float) -> str:
    """Return the process's output up to the line containing mark (or its end)."""
    out = ''
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        while mark not in out and time.monotonic() < deadline:
            if sel.select(timeout=deadline - time.monotonic()):
                line = proc.stdout.readline()
                if not line:
                    break
                out += line
    return out


@pytest.mark.slow
@pytest.mark.parametrize('executor', ['single', 'events'])
@pytest.mark.parametrize('hang_on', ['MEAS:POW?', 'SYST:ERR?'])     # reading, configuring
@pytest.mark.parametrize('run', [1, 2])
def test_ctrl_c_while_a_query_hangs_exits_0_without_a_traceback(executor, hang_on, run):
    code = f'import sys; sys.path.insert(0, {str(TEST_DIR)!r}); import visa_faults; ' \
           f'visa_faults.run_hanging_driver({hang_on!r})'
    proc = subprocess.Popen([sys.executable, '-c', code, '--executor', executor,
                             '--ros-args', '-p', 'rate:=50.0', '-p', 'timeout:=3.0'],
                            cwd=REPO, env={**os.environ, 'PYTHONUNBUFFERED': '1'},
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        out = lines_until(proc, HANG_MARK, time.monotonic() + TIMEOUT)
        assert HANG_MARK in out, out
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    out += rest
    assert proc.returncode == 0, out
    for bad in ('FATAL', 'Traceback', 'Error occurred', 'KeyboardInterrupt', 'RCLError'):
        assert bad not in out, out
