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
What the nodes share: the executors (`--executor single|events`), --help, parameter files.

The other node tests run on both executors through the `executor_kind` fixture (conftest):
the clock-jump reset (use_sim_time and /clock) in test_timescale_estimator and
test_alignment, ~/reset and ~/enable in test_timescale_estimator_parameters and
test_alignment.  Here: what only a running process or a service client shows.
"""

import gc
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from node_helpers import run_node, spin_until, stop
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile

from tskf_ros.core import jit
from tskf_ros.nodes import node_runner
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / 'config'
TIMEOUT = 60.0      # s: only a bound on waiting for DDS or a process; no timed assertion


def from_estimator(diagnostics):
    """Return whether a /diagnostics message of the estimator came."""
    return any(s.name.startswith('timescale_estimator') for m in diagnostics for s in m.status)


def test_timer_and_parameter_services(ros_context, executor_kind):
    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('diagnostic_updater.period', value=0.05)])
    client = rclpy.create_node('parameter_client', context=ros_context)
    diagnostics = []
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append,
                               QoSProfile(depth=100))
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(node)
    executor.add_node(client)
    params = AsyncParameterClient(client, 'timescale_estimator')
    try:
        # the diagnostics timer fires, again and again
        spin_until(executor, lambda: len(diagnostics) >= 3, 'three /diagnostics messages')
        spin_until(executor, lambda: params.services_are_ready(), 'the parameter services')
        future = params.set_parameters([Parameter('transition', value='exact')])
        spin_until(executor, future.done, 'set_parameters')
        assert future.result().results[0].successful
        assert node.session.kf.transition == 'exact'
        future = params.set_parameters([Parameter('Q', value=[1.0, 2.0])])
        spin_until(executor, future.done, 'set_parameters (refused)')
        result = future.result().results[0]
        assert not result.successful and 'Q must have 1 entries' in result.reason
        future = params.get_parameters(['transition', 'Q'])
        spin_until(executor, future.done, 'get_parameters')
        values = future.result().values
        assert values[0].string_value == 'exact' and list(values[1].double_array_value) == [1.0]
    finally:
        executor.shutdown()
        node.destroy_node()
        client.destroy_node()


def start(args, log, env=None):
    """Start the estimator as a process (output to the log file)."""
    return subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator', *args, '--ros-args',
         '-p', 'diagnostic_updater.period:=0.1'], cwd=REPO, env=env or dict(os.environ),
        stdout=log, stderr=subprocess.STDOUT, text=True)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.parametrize('how', ['flag', 'environment'])
def test_the_node_process_stops_cleanly(ros_context, tmp_path, executor_kind, sig, how):
    log = (tmp_path / 'node.log').open('w+')
    env = dict(os.environ)
    env.pop(node_runner.EXECUTOR_VARIABLE, None)
    if how == 'flag':
        proc = start(['--executor', executor_kind], log, env)
    else:
        env[node_runner.EXECUTOR_VARIABLE] = executor_kind
        proc = start([], log, env)
    client = rclpy.create_node('watcher', context=ros_context)
    diagnostics = []
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append,
                               QoSProfile(depth=10))
    executor = make_executor('single', context=ros_context)
    executor.add_node(client)
    try:
        # spinning: its timer publishes
        spin_until(executor, lambda: from_estimator(diagnostics) or proc.poll() is not None,
                   'the node process to publish /diagnostics')
        assert proc.poll() is None, 'the node process ended by itself'
    finally:
        executor.shutdown()
        client.destroy_node()
        out = stop(proc, log, sig)
        log.close()
    assert proc.returncode == 0 and 'Traceback' not in out, out


def test_an_unknown_executor_is_refused_in_one_line():
    env = dict(os.environ)
    env[node_runner.EXECUTOR_VARIABLE] = 'threads'
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator'],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 1
    assert proc.stderr.strip() == ('timescale_estimator: cannot start: executor must be one '
                                   "of single, events, got 'threads'")


def test_an_unknown_jit_mode_ends_the_node_with_one_line():
    env = dict(os.environ)
    env[jit.MODE_VARIABLE] = 'fast'
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator'],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 1
    assert proc.stderr.strip() == ('timescale_estimator: cannot start: TSKF_JIT: jit mode must '
                                   "be one of wait, background, off, got 'fast'")


def test_the_default_executor_and_the_environment(monkeypatch):
    monkeypatch.delenv(node_runner.EXECUTOR_VARIABLE, raising=False)
    assert node_runner.executor_kind() == node_runner.DEFAULT_EXECUTOR
    monkeypatch.setenv(node_runner.EXECUTOR_VARIABLE, 'single')
    assert node_runner.executor_kind() == 'single'
    assert node_runner.executor_kind('events') == 'events'     # the flag wins


@pytest.mark.parametrize('module', ['timescale_estimator', 'power_meter_simulator'])
def test_help_exits_0_without_ros(module):
    code, out = run_node(module, '--help')
    assert code == 0 and 'usage' in out


def test_a_parameter_file_that_sets_nothing_is_said_loudly(tmp_path):
    from tskf_ros.nodes.node_runner import unused_parameter_file
    wrong = tmp_path / 'wrong.yaml'
    wrong.write_text('some_other_node:\n  ros__parameters:\n    period: 2.0\n')
    for path, expect_warning in ((wrong, True), (CONFIG / 'owc_estimator.yaml', False)):
        argv = ['--ros-args', '--params-file', str(path)]
        context = rclpy.context.Context()
        rclpy.init(context=context, args=argv)
        try:
            node = TimescaleEstimator(context=context)
            try:
                warning = unused_parameter_file(node, argv)
                assert bool(warning) == expect_warning, warning
                if expect_warning:
                    assert 'set none of the parameters of /timescale_estimator' in warning
            finally:
                node.destroy_node()
        finally:
            context.try_shutdown()


def test_the_default_executor_spins_without_a_polling_loop(monkeypatch, ros_context):
    # SingleThreadedExecutor.spin() returns on SIGINT and SIGTERM by itself; only the
    # EventsExecutor needs node_runner.spin's loop of spin_once calls with a timeout
    monkeypatch.delenv(node_runner.EXECUTOR_VARIABLE, raising=False)
    assert node_runner.DEFAULT_EXECUTOR == 'single'
    calls = []

    class Recorder(rclpy.executors.SingleThreadedExecutor):
        def spin(self):
            calls.append('spin')

        def spin_once(self, timeout_sec=None):
            calls.append('spin_once')

    executor = Recorder(context=ros_context)
    try:
        node_runner.spin(executor, ros_context)
    finally:
        executor.shutdown()
    assert calls == ['spin']
    default = make_executor(None, context=ros_context)
    try:
        assert type(default) is rclpy.executors.SingleThreadedExecutor
    finally:
        default.shutdown()


# a malformed ROS argument on the command line of each node: rcl's RCLInvalidROSArgsError
# and UnknownROSArgsError escaped run_node as a traceback
MALFORMED = [
    ('timescale_estimator', ['-p', 'period:=['], "'-p period:=['"),
    ('power_meter_simulator', ['-p', 'period:=['], "'-p period:=['"),
    ('led_link_simulator', ['-p', 'period:=['], "'-p period:=['"),
    ('alignment', ['-p', 'period:=['], "'-p period:=['"),
    ('power_meter_driver', ['-p', 'backend:=@py'], "'-p backend:=@py'"),
    ('timescale_estimator', ['-p', 'backend:=@py'], "'-p backend:=@py'"),
    ('timescale_estimator', ['-p', 'gate'], "'-p gate'"),
    ('power_meter_driver', ['-r', 'a:='], "'-r a:='"),
    ('alignment', ['--no-such-flag'], "'--no-such-flag'"),
]


@pytest.mark.parametrize('module, ros_args, named', MALFORMED,
                         ids=[f'{m}{"".join(a)}' for m, a, _ in MALFORMED])
def test_a_malformed_ros_argument_is_one_line_and_exit_2(module, ros_args, named):
    proc = subprocess.run([sys.executable, '-m', f'tskf_ros.nodes.{module}', '--ros-args',
                           *ros_args], cwd=REPO, env=dict(os.environ), capture_output=True,
                          text=True, timeout=TIMEOUT)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == node_runner.EXIT_USAGE == 2, proc.stderr
    assert len(lines) == 1 and 'Traceback' not in proc.stderr + proc.stdout, proc.stderr
    assert lines[0].startswith(f'{module}: cannot start: '), lines[0]
    assert named in lines[0] and '.c:' not in lines[0], lines[0]


def test_the_node_reads_the_clock_of_the_source_in_force(ros_context):
    # ROS time inactive: the system clock, read without rclpy; active (use_sim_time, no
    # /clock yet): the node clock's now(), 0 until /clock says otherwise
    node = TimescaleEstimator(context=ros_context)
    try:
        assert node.now_ns is time.time_ns
        before = time.time_ns()
        assert before <= node.now_ns() <= node.clock_ns() <= time.time_ns()
        node.set_parameters([Parameter('use_sim_time', value=True)])
        assert node.get_clock().ros_time_is_active
        assert node.now_ns() == node.clock_ns() == 0
        node.set_parameters([Parameter('use_sim_time', value=False)])
        assert node.now_ns is time.time_ns
    finally:
        node.destroy_node()


def test_own_process_freezes_the_heap_now_and_after_the_first_sample(ros_context):
    """gc.freeze() at the call and again at the first /diagnostics after a sample."""
    node = TimescaleEstimator(context=ros_context)
    try:
        gc.unfreeze()
        node.publish_diagnostics()
        assert gc.get_freeze_count() == 0 and not node.freeze_heap    # not the node's own
        node.own_process()
        assert node.freeze_heap and gc.get_freeze_count() > 0
        gc.unfreeze()
        node.publish_diagnostics()          # no sample yet: the flag stays
        assert node.freeze_heap and gc.get_freeze_count() == 0
        node.session.add(1_000_000_000, 165.0)
        node.publish_diagnostics()
        assert not node.freeze_heap and gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()                       # the test process's collector as it was
        node.destroy_node()


def test_when_spinning_runs_once_from_the_executor_not_before(ros_context, executor_kind):
    node = TimescaleEstimator(context=ros_context)
    ran = []
    node.when_spinning(lambda: ran.append(len(ran)))
    assert ran == []                    # nothing at the call: the constructor stays short
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(node)
    try:
        spin_until(executor, lambda: len(ran) >= 1, 'the deferred action')
        for _ in range(20):
            executor.spin_once(timeout_sec=0.01)
        assert ran == [0]               # once, whatever the executor's turns after
    finally:
        executor.shutdown()
        node.destroy_node()
