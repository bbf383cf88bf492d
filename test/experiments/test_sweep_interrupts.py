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
sweep: Ctrl-C in each phase of a Dask sweep is one line, and leaves nothing running.

A terminal's Ctrl-C goes to the whole foreground process group: the sweep, its Dask
workers and multiprocessing's resource tracker.  The sweep is started in a session of its
own and the group is sent SIGINT once a phase is reached (a condition polled with a
deadline, never a sleep).  Before: a Ctrl-C while the cluster started was ignored (the
sweep ran to its end), and one just after it left the cluster unclosed: the workers
logged heartbeat tracebacks and the resource tracker warned of leaked semaphores.
"""

import csv
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time

import pytest
from stderr_lines import error_lines
from tskf_ros.experiments import sweep

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / 'bags' / 'owc_cai_td_1hz'
PARAMS = REPO / 'config' / 'owc_estimator.yaml'
# s: a bound on waiting for a subprocess or a condition, never an assertion about timing
TIMEOUT = 120.0
POLL = 0.02         # s between two looks at a condition (not a synchronisation)


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Two copies of the 1 Hz sample bag."""
    d = tmp_path_factory.mktemp('pair')
    for name in ('a', 'b'):
        shutil.copytree(SAMPLE, d / name)
    return d


def group(pgid: int) -> list:
    """Return the pids of the processes of process group pgid."""
    pids = []
    for entry in os.listdir('/proc'):
        try:
            stat = Path('/proc', entry, 'stat').read_text()
        except (OSError, ValueError):
            continue                        # not a process, or gone meanwhile
        fields = stat.rpartition(')')[2].split()
        if entry.isdigit() and int(fields[2]) == pgid:
            pids.append(int(entry))
    return pids


def rows(out: Path) -> int:
    try:
        return len(out.read_text().splitlines())
    except OSError:
        return -1


def interrupt(argv: list, out: Path, ready) -> tuple:
    """Run the sweep; SIGINT its group once ready(pid) holds; return (status, stderr)."""
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.experiments.sweep', *argv, '--out', str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    try:
        deadline = time.monotonic() + TIMEOUT
        while not ready(proc.pid):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, 'the phase was never reached'
            time.sleep(POLL)            # polling a condition, with a deadline
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=TIMEOUT)
        # every process of the group ends: the workers and the resource tracker too
        while group(proc.pid):
            assert time.monotonic() < deadline, f'left running: {group(proc.pid)}'
            time.sleep(POLL)
    finally:
        if proc.poll() is None or group(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    return proc.returncode, err


def check_one_line(status: int, err: str, out: Path) -> None:
    """One line saying how many whole rows are kept; nothing else on stderr."""
    assert 'resource_tracker' not in err and 'ERROR' not in err, err
    lines = error_lines(err)
    assert status == 130 and len(lines) == 1, err
    with open(out, newline='') as f:
        table = list(csv.reader(f))
    assert len({len(r) for r in table}) == 1, table        # whole rows under the header
    assert lines[0] == (f'sweep: interrupted: {len(table) - 1} rows in {out} kept; the same '
                        'command resumes')


def sweep_argv(bags: Path, settings: int, *more: str) -> list:
    return ['--bags', str(bags), '--params-file', str(PARAMS), '--set',
            'R=' + ','.join(str(r) for r in range(1, settings + 1)), '--workers', '2', *more]


def test_ctrl_c_while_the_workers_start_stops_the_sweep_in_one_line(bags, tmp_path):
    # the table exists and a process of the cluster (a worker, the resource tracker) has
    # started, no row yet: the cluster is starting, or the client connecting to it
    out = tmp_path / 'start.csv'
    status, err = interrupt(sweep_argv(bags, 400), out,
                            lambda pid: rows(out) == 1 and len(group(pid)) >= 2)
    check_one_line(status, err, out)


def test_ctrl_c_while_rows_come_is_one_line_without_worker_tracebacks(bags, tmp_path):
    out = tmp_path / 'rows.csv'
    status, err = interrupt(sweep_argv(bags, 400), out, lambda pid: rows(out) >= 3)
    check_one_line(status, err, out)


def test_ctrl_c_once_every_row_is_in_ends_quietly(bags, tmp_path):
    # the cluster closing, the figure being drawn, or the sweep already done (then the
    # Ctrl-C is not the sweep's: exit 0 and nothing on stderr)
    out, png = tmp_path / 'done.csv', tmp_path / 'done.png'
    status, err = interrupt(sweep_argv(bags, 3, '--png', str(png)), out,
                            lambda pid: rows(out) == 7)
    if status == 0:
        assert err == '' and png.is_file()
    else:
        check_one_line(status, err, out)


def test_ctrl_c_before_the_table_exists_says_nothing_was_written(
        bags, tmp_path, capsys, monkeypatch):
    def interrupted(patterns):
        raise KeyboardInterrupt
    monkeypatch.setattr(sweep, 'find_bags', interrupted)
    out = tmp_path / 'none.csv'
    assert sweep.main(sweep_argv(bags, 2, '--out', str(out))) == 130
    assert capsys.readouterr().err == 'sweep: interrupted: nothing written\n'
    assert not out.exists()


def test_ctrl_c_while_the_figure_is_drawn_keeps_the_whole_table(
        bags, tmp_path, capsys, monkeypatch):
    def interrupted(rows, sets, path):
        raise KeyboardInterrupt
    monkeypatch.setattr(sweep, 'plot', interrupted)
    out, png = tmp_path / 'fig.csv', tmp_path / 'fig.png'
    argv = ['--bags', str(bags), '--params-file', str(PARAMS), '--set', 'R=1,2',
            '--workers', '0', '--out', str(out), '--png', str(png), '--no-progress']
    assert sweep.main(argv) == 130
    assert capsys.readouterr().err == (f'sweep: interrupted: 4 rows in {out} kept; the same '
                                       'command resumes\n')
    assert not png.exists()
