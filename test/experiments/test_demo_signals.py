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
The demo under Ctrl-C: in each phase, to its process group or to the demo process alone.

The demo runs as `./run demo` runs it (the console's runner, --reproduce first).  Before:
a Ctrl-C during the live pipeline aborted it ("terminate called without an active
exception", exit 134), and one to the demo alone left the alignment and LED simulator
processes running.  Every wait is a condition with a deadline.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time

import pytest

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 120.0     # s: a bound on a phase being reached on a loaded machine, not a result
STOPPED = 30.0      # s: the demo and its children end within this of the signal
RUN = ('from tskf_ros.tools.console import run_as_main\n'
       'run_as_main(lambda: __import__("tskf_ros.experiments.demo", fromlist=["main"])'
       '.main())')
# the line each phase begins with, and how many children it has running by then
PHASES = {'reproduce': ('demo: python -m tskf_ros.experiments.reproduce', 1),
          'live': ('demo: to watch it live', 3),
          'bag': ('replaying the sample bag', 0)}


def children(pid):
    """Return the pids of pid's child processes (from /proc)."""
    out = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry.name))
    return out


def alive(pid):
    """Tell whether pid runs (a zombie does not)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


def wait(condition, what, timeout=TIMEOUT):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.1)


@pytest.mark.slow
@pytest.mark.parametrize('phase', sorted(PHASES))
@pytest.mark.parametrize('target', ['group', 'demo'])
def test_ctrl_c_in_any_phase_ends_every_child_with_130(phase, target, tmp_path):
    log = tempfile.TemporaryFile('w+', dir=tmp_path)
    args = ['--duration', '20', '--led-duration', '10', '--out', str(tmp_path / 'out'),
            '--reproduce', '--iterations', '20', '--long-iterations', '40']
    demo = subprocess.Popen([sys.executable, '-c', RUN, *args], cwd=tmp_path,
                            env={**os.environ, 'PYTHONPATH': str(REPO)}, stdout=log,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    marker, running = PHASES[phase]

    def output():
        log.seek(0)
        return log.read()
    try:
        wait(lambda: marker in output() or demo.poll() is not None, f'the {phase} phase')
        assert demo.poll() is None, output()
        wait(lambda: len(children(demo.pid)) >= running, f'{running} children')
        kids = children(demo.pid)
        if target == 'group':
            os.killpg(demo.pid, signal.SIGINT)
        else:
            demo.send_signal(signal.SIGINT)
        status = demo.wait(timeout=STOPPED)
        wait(lambda: not any(alive(k) for k in kids), 'the children to end', STOPPED)
    finally:
        if demo.poll() is None:
            os.killpg(demo.pid, signal.SIGKILL)
    text = output()
    assert status == 130, text[-3000:]
    assert 'terminate called' not in text and 'Traceback' not in text, text[-3000:]
