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

"""What the node tests share: a node as a process (start, run, stop) and a service call."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

REPO = Path(__file__).resolve().parents[2]
# s: a bound on waiting for DDS or a process (discovery, matching, delivery), never an
# assertion about timing; generous for a loaded 2-core machine, it costs nothing when
# things work
TIMEOUT = 60.0


def node_process(module, *args, log):
    """Start python -m tskf_ros.nodes.<module> with this run's ROS environment."""
    # the output goes to a file, not a pipe: a pipe nobody reads while the test runs would
    # block the node once it filled up (every duplicate it drops is a warning line)
    return subprocess.Popen([sys.executable, '-m', f'tskf_ros.nodes.{module}', *args],
                            cwd=REPO, env=dict(os.environ), stdout=log,
                            stderr=subprocess.STDOUT, text=True)


def run_node(module, *args):
    """Run python -m tskf_ros.nodes.<module> to its end; return (exit status, output)."""
    proc = subprocess.run([sys.executable, '-m', f'tskf_ros.nodes.{module}', *args],
                          cwd=REPO, env=dict(os.environ), stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=TIMEOUT)
    return proc.returncode, proc.stdout


def stop(proc, log, sig=signal.SIGINT):
    """Signal the node process (SIGINT), wait (killing it if it hangs); return its output."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        proc.wait(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=TIMEOUT)
        log.seek(0)
        raise AssertionError(f'the node ignored {sig.name} for {TIMEOUT:g} s:\n{log.read()}')
    log.seek(0)
    return log.read()


def call(executor, client, request):
    """Call a service from a client on the executor; return the response."""
    deadline = time.monotonic() + TIMEOUT
    while not client.service_is_ready():
        assert time.monotonic() < deadline, f'{client.srv_name} never became ready'
        executor.spin_once(timeout_sec=0.05)
    future = client.call_async(request)
    while not future.done():
        assert time.monotonic() < deadline, f'{client.srv_name} never answered'
        executor.spin_once(timeout_sec=0.05)
    return future.result()


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    deadline = time.monotonic() + TIMEOUT
    while not condition():
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        executor.spin_once(timeout_sec=0.05)
