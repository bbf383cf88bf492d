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
"""How a node runs: unknown parameter names said once each, a value rcl drops, BLAS threads."""

import sys

from node_helpers import run_node
import pytest
import rclpy

from tskf_ros.nodes import node_runner
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator


@pytest.fixture
def node_with_args(tmp_path):
    """Build the estimator under a command line, as run_node does; destroy it after."""
    made = []

    def factory(argv):
        context = rclpy.context.Context()
        rclpy.init(context=context, args=argv)
        node = TimescaleEstimator(context=context)
        made.append((context, node))
        return node
    yield factory
    for context, node in made:
        node.destroy_node()
        context.try_shutdown()


def test_each_unknown_parameter_gets_one_warning_with_the_closest_name(
        node_with_args, tmp_path):
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    queue_dept: 5\n    history_size: 20\n'
                      '    frobnicate: 1\nother_node:\n  ros__parameters:\n    nonsense: 1\n')
    argv = ['timescale_estimator', '--ros-args', '--params-file', str(params),
            '-p', 'status_perod:=2.0', '-p', 'timescale_estimator:frame_idd:=x',
            '-p', 'other_node:period:=1.0', '-p', 'status_period:=3.0',
            '-p', 'qos_overrides./estimate/correctd.publisher.depth:=3']
    node = node_with_args(argv)
    assert node.get_parameter('history_size').value == 20     # the file is read
    warnings = node_runner.unknown_parameters(node, argv)
    assert len(warnings) == 5, warnings
    by_name = {w.split("'")[1]: w for w in warnings}
    assert set(by_name) == {'queue_dept', 'frobnicate', 'status_perod', 'frame_idd',
                            'qos_overrides./estimate/correctd.publisher.depth'}
    assert by_name['queue_dept'].endswith("did you mean 'queue_depth'?")
    assert f'({params})' in by_name['queue_dept']
    assert by_name['status_perod'].endswith("did you mean 'status_period'?")
    assert '(-p status_perod:=2.0)' in by_name['status_perod']
    assert by_name['frame_idd'].endswith("did you mean 'frame_id'?")
    assert by_name['qos_overrides./estimate/correctd.publisher.depth'].endswith(
        "did you mean 'qos_overrides./estimate/corrected.publisher.depth'?")
    assert 'did you mean' not in by_name['frobnicate']
    assert all('/timescale_estimator and is ignored' in w for w in warnings)


def test_declared_parameters_and_other_nodes_parameters_are_not_warned(node_with_args):
    argv = ['x', '--ros-args', '-p', 'queue_depth:=5', '-p', 'other:nonsense:=1', '--',
            '-p', 'not_a_ros_argument:=1']
    node = node_with_args(argv)
    assert node_runner.unknown_parameters(node, argv) == []


@pytest.mark.parametrize('args, file, why', [
    # rcl drops an empty list (it has no parameter type): the node ran on its default Q
    (['-p', 'Q:=[]'], None, 'Q (-p Q:=[]) did not reach the node: rcl drops an empty list '
     '(it has no parameter type), so it would run with Q = [1]; give Q its entries, or '
     'leave it out'),
    (['--params-file', '{file}'], 'Q: []', 'Q ({file}) did not reach the node: rcl drops an '
     'empty list (it has no parameter type), so it would run with Q = [1]; give Q its '
     'entries, or leave it out'),
    # the file's value arrives, not the -p that was to replace it
    (['--params-file', '{file}', '-p', 'B:=[]'], 'B: [2.0]',
     'B (-p B:=[]) did not reach the node: rcl drops an empty list (it has no parameter '
     'type), so it would run with B = [2]; give B its entries, or leave it out'),
    # a -p for the node by name drops the file's value too: the default is left
    (['--params-file', '{file}', '-p', 'timescale_estimator:Q:=[ ]'], 'Q: [3.0]',
     'Q (-p timescale_estimator:Q:=[ ]) did not reach the node: rcl drops an empty list (it '
     'has no parameter type), so it would run with Q = [1]; give Q its entries, or leave '
     'it out'),
    # a scalar given for it: as for any list
    (['-p', 'period:=[]'], None, 'period (-p period:=[]) did not reach the node: rcl drops '
     'an empty list (it has no parameter type), so it would run with period = 1; give '
     'period its entries, or leave it out'),
    # an empty list where the value is an empty list anyway, another node's, or values that
    # arrive (a file and -p, scalars and lists): started
    (['--params-file', '{file}', '-p', 'period:=2.0', '-p', 'x0:=[3.0]',
      '-p', 'frame_id:=f'], 'gate: 5.0', ''),
    (['-p', 'B:=[]'], None, ''),
    (['--params-file', '{file}', '-p', 'timescale_estimator:B:=[ ]'], 'B: [2.0]', ''),
    (['-p', 'other:Q:=[]'], None, ''),
    (['-p', 'Q:=[2.0]'], 'Q: []', '')])
def test_a_parameter_rcl_drops_is_refused_at_start(node_with_args, tmp_path, args, file, why):
    params = tmp_path / 'p.yaml'
    if file is not None:
        params.write_text(f'/**:\n  ros__parameters:\n    {file}\n')
    argv = ['timescale_estimator', '--ros-args',
            *(a.replace('{file}', str(params)) for a in args)]
    node = node_with_args(argv)
    assert node_runner.dropped_parameters(node, argv) == why.replace('{file}', str(params))


def test_a_dropped_parameter_ends_the_node_with_one_line():
    code, out = run_node('timescale_estimator', '--ros-args', '-p', 'Q:=[]')
    assert code == 1 and out.splitlines() == [
        'timescale_estimator: cannot start: Q (-p Q:=[]) did not reach the node: rcl drops '
        'an empty list (it has no parameter type), so it would run with Q = [1]; give Q its '
        'entries, or leave it out'], out


def test_without_threadpoolctl_the_node_warns_unless_blas_is_told(monkeypatch):
    monkeypatch.setitem(sys.modules, 'threadpoolctl', None)   # import: ModuleNotFoundError
    for name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS'):
        monkeypatch.delenv(name, raising=False)
    warning = node_runner.limit_blas_threads()
    assert 'threadpoolctl is not installed' in warning and 'tskf_ros[threads]' in warning
    monkeypatch.setenv('OPENBLAS_NUM_THREADS', '1')
    assert node_runner.limit_blas_threads() == ''


# A SIGINT whose KeyboardInterrupt is lost: SIGUSR1 in the child runs what the runner's
# handler does (SigintFlag: the event set, then `first`) without the raise, as a weakref
# callback's report swallows it.  The unconfigured driver's wait set has nothing else to
# wake it, so only the context's shutdown can end its spin.
LOSE_AN_INTERRUPT = """
import signal
def lose(signum, frame):
    owner = signal.getsignal(signal.SIGINT).__self__
    owner.event.set()
    if owner.first is not None:
        owner.first()
signal.signal(signal.SIGUSR1, lose)
from tskf_ros.tools.console import power_meter_driver
power_meter_driver()
"""


def test_a_sigint_whose_interrupt_is_lost_still_ends_the_node(tmp_path):
    """The context is shut down SIGINT_GRACE after the SIGINT: the spin returns, exit 0."""
    import os
    from pathlib import Path
    import signal
    import subprocess
    import time
    repo = Path(__file__).resolve().parents[2]
    log = tmp_path / 'driver.log'
    with open(log, 'w') as out:
        proc = subprocess.Popen(
            [sys.executable, '-c', LOSE_AN_INTERRUPT, '--ros-args', '-p',
             f'backend:={repo}/config/pm100_sim.yaml@sim', '-p', 'autostart:=false',
             '-p', 'status_period:=0.0'],
            cwd=repo, env=dict(os.environ), stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60.0
        while 'driver of' not in log.read_text() and proc.poll() is None:
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)        # polling the log for the start line, not a synchronisation
        proc.send_signal(signal.SIGUSR1)
        status = proc.wait(timeout=30.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert status == 0, log.read_text()
