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

"""Build the package with colcon and run each executable the way `ros2 run` finds it."""

import ast
import os
from pathlib import Path
import shutil
import subprocess
import sys

from entry_points import console_script_targets, console_scripts
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
PACKAGE = 'tskf_ros'
NOT_COPIED = shutil.ignore_patterns(
    '.git', '.venv', '.venv-floor', '.pytest_cache', '.mypy_cache', 'results', 'build',
    'install', 'log', '__pycache__', '*.egg-info', '_build')
# `colcon test`'s bound: about 10 min on an idle 2-core machine, 21 min at load 5
COLCON_TEST_TIMEOUT = 2700.0
# a test that runs longer than this under colcon dumps every thread's stack into the log
# (pytest's faulthandler_timeout), so that a hang shows where it is
HANG_DUMP_AFTER = 600
# What `ros2 run PACKAGE EXE` does: look EXE up in <package prefix>/lib/PACKAGE.
LIB_DIR = (
    'import os, sys; '
    'from ament_index_python.packages import get_package_prefix; '
    "print(os.path.join(get_package_prefix(sys.argv[1]), 'lib', sys.argv[1]))"
)

pytestmark = [pytest.mark.colcon, pytest.mark.slow]

# What each executable's --help must name: its parameters file (the nodes, which take ROS
# parameters) or its real options (the programs).
HELP_MUST_NAME = {
    'reproduce': ('--out', '--seed', '--noise-scaling', '--td-dense-step'),
    'power_meter_simulator': ('--ros-args --params-file', 'config/power_meter_simulator.yaml'),
    'timescale_estimator': ('--ros-args --params-file', 'config/owc_estimator.yaml'),
    'record': ('-o OUTPUT', '--overwrite', '--topics', '--max-bag-size', '--compression-mode'),
    'play': ('--rate', '--loop', '--remap', 'bag', '--clock [HZ]', '--start-paused'),
    'replay_offline': ('--filter {estimator,alignment}', '--params-file', '--topic'),
    'plot_bag': ('--out', '--params-file', 'bag'),
    'make_sample_bags': ('--out', '--seed', '--only'),
    'led_link_simulator': ('--ros-args --params-file', 'config/led_link_simulator.yaml'),
    'alignment': ('--ros-args --params-file', 'config/alignment.yaml'),
    'reindex': ('-o OUTPUT', 'path', '.partial'),
    'power_meter_driver': ('--ros-args --params-file', 'config/power_meter_driver.yaml',
                           'pm100_sim.yaml@sim'),
    'fit_noise': ('--params-file', '--topic', '--out', '--json', 'bag'),
    'sweep': ('--bags', '--set', '--workers', '--scheduler', '--out', '--png'),
    'foxglove_bridge': ('--ros-args', 'ws://localhost:8765', 'port (8765)',
                        "topics (['*'])"),
}


def in_sourced_workspace(install, *command, timeout=120):
    """Run command in bash after sourcing install/setup.bash, as a user of the workspace would."""
    return subprocess.run(
        ['bash', '-c', 'source "$0/setup.bash" && exec "$@"', str(install), *command],
        env=build_env(install.parent), capture_output=True, text=True, timeout=timeout)


def run_in_own_session(command, cwd, env, log, timeout):
    """
    Run command with its output into log; past timeout s end it and everything it started.

    colcon's pytest and the node processes of the tests are grandchildren: a session of
    their own lets one signal to the process group end them all (and subprocess.run's
    timeout would end colcon alone).  Return the exit status (-9 after the timeout).
    """
    import signal

    with open(log, 'w') as out:
        proc = subprocess.Popen(command, cwd=cwd, env=env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            return proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            # first SIGABRT to the group: Python's faulthandler (PYTHONFAULTHANDLER) prints
            # the stacks of each process that hangs, then SIGKILL
            os.killpg(proc.pid, signal.SIGABRT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            out.write(f'\n[test] colcon test ran past {timeout:.0f} s: ended\n')
            return -9
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def build_env(workspace):
    """Return the environment for colcon and the built executables: this interpreter first."""
    env = dict(os.environ)
    env['PATH'] = os.path.dirname(sys.executable) + os.pathsep + env.get('PATH', '')
    env['COLCON_HOME'] = str(workspace / 'colcon_home')  # ignore the user's colcon defaults
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
    return env


@pytest.fixture(scope='module')
def install(tmp_path_factory):
    """Build a workspace with this package in src/ using colcon; return its install dir."""
    workspace = tmp_path_factory.mktemp('ws')
    shutil.copytree(REPO_ROOT, workspace / 'src' / PACKAGE, ignore=NOT_COPIED)
    result = subprocess.run(
        [sys.executable, '-m', 'colcon', '--log-base', str(workspace / 'log'), 'build',
         '--base-paths', str(workspace / 'src'),
         '--build-base', str(workspace / 'build'),
         '--install-base', str(workspace / 'install'),
         '--event-handlers', 'console_direct+'],
        cwd=workspace, env=build_env(workspace), capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, 'colcon build failed:\n' + result.stdout + result.stderr
    return workspace / 'install'


def test_the_nodes_kernels_are_compiled_into_the_install(install):
    """The workspace's build compiled the nodes' kernels ahead of time into its install."""
    import sysconfig

    pytest.importorskip('numba', reason='numba is not installed: the build compiles nothing')
    compiler = (os.environ.get('CC') or sysconfig.get_config_var('CC') or 'cc').split()[0]
    if shutil.which(compiler) is None:
        pytest.skip(f'no C compiler ({compiler}): the build compiles nothing')
    code = ('import sys; from tskf_ros.core import aot; module = aot.load(); '
            'print(module.__file__ if module else None); print("numba" in sys.modules)')
    # -P: not the working directory's tskf_ros (a checkout's) but the workspace's
    result = in_sourced_workspace(install, sys.executable, '-P', '-c', code)
    assert result.returncode == 0, result.stdout + result.stderr
    path, numba_loaded = result.stdout.split()
    # <install>/tskf_ros/lib/pythonX.Y/site-packages/tskf_ros/core/__pycache__/<module>
    assert Path(path).is_relative_to(install / PACKAGE), path
    assert Path(path).parts[-4:-1] == (PACKAGE, 'core', '__pycache__'), path
    assert numba_loaded == 'False'


def test_the_install_has_bytecode_and_scripts_that_import_directly(install):
    """setup.py writes the modules' bytecode and console scripts without a metadata lookup."""
    nodes = next((install / PACKAGE / 'lib').glob(f'python3*/site-packages/{PACKAGE}/nodes'))
    pyc = sorted(p.name for p in (nodes / '__pycache__').glob('*.pyc'))
    assert {f'{p.stem}.{sys.implementation.cache_tag}.pyc' for p in nodes.glob('*.py')} \
        <= set(pyc), pyc
    for name, target in console_script_targets().items():
        module, function = target.split(':')
        text = (install / PACKAGE / 'lib' / PACKAGE / name).read_text()
        assert f'from {module} import {function}' in text, text
        assert 'importlib' not in text and 'pkg_resources' not in text, text


def test_setup_declares_executables():
    assert console_scripts(), 'setup.py declares no console_scripts'


def test_package_files_installed(install):
    assert (install / 'setup.bash').is_file()
    share = install / PACKAGE / 'share'
    assert (share / PACKAGE / 'package.xml').is_file()
    assert (share / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()


def test_package_found_through_ament_index(install):
    result = in_sourced_workspace(install, sys.executable, '-c', LIB_DIR, PACKAGE)
    assert result.returncode == 0, result.stdout + result.stderr
    assert Path(result.stdout.strip()) == install / PACKAGE / 'lib' / PACKAGE


@pytest.mark.parametrize('executable', console_scripts())
def test_executable_runs_like_ros2_run(install, executable):
    result = in_sourced_workspace(install, sys.executable, '-c', LIB_DIR, PACKAGE)
    assert result.returncode == 0, result.stdout + result.stderr
    path = Path(result.stdout.strip()) / executable
    assert path.is_file(), f'{path} is not installed'
    assert os.access(path, os.X_OK), f'{path} is not executable'

    result = in_sourced_workspace(install, str(path), '--help')
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert result.stdout.startswith(f'usage: {executable} '), output
    flat = ' '.join(result.stdout.split())      # argparse wraps long lines
    for text in HELP_MUST_NAME.get(executable, ('(no expectations: add them)',)):
        assert text in flat, f'{executable} --help does not name {text!r}:\n{output}'


def test_every_executable_has_its_help_expectations():
    missing = sorted(set(console_scripts()) - set(HELP_MUST_NAME))
    assert not missing, f'add what --help must name for {missing} to HELP_MUST_NAME'


def test_launch_files_are_installed_and_name_installed_executables(install):
    share = install / PACKAGE / 'share' / PACKAGE
    lib = install / PACKAGE / 'lib' / PACKAGE
    for path in sorted((REPO_ROOT / 'launch').glob('*.launch.py')):
        assert (share / 'launch' / path.name).is_file(), path.name
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.keyword) and node.arg == 'executable':
                assert (lib / ast.literal_eval(node.value)).is_file(), (path.name, node.value)
            if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                    and node.value.endswith('.yaml')):
                assert (share / 'config' / node.value).is_file(), (path.name, node.value)


def test_readme_ros2_run_names_are_found_through_ament_index(install):
    # the `ros2 run tskf_ros NAME` commands of the README and doc/ (test_command_names
    # checks the venv's)
    from documented_commands import documentation, named, placeholder, readme_commands
    ros2_run = {name for text in documentation().values()
                for name in named(readme_commands(text))[1] if not placeholder(name)}
    assert {'record', 'play'} <= ros2_run
    result = in_sourced_workspace(install, sys.executable, '-c', LIB_DIR, PACKAGE)
    assert result.returncode == 0, result.stdout + result.stderr
    lib = Path(result.stdout.strip())
    missing = sorted(name for name in ros2_run if not (lib / name).is_file())
    assert not missing, f'the documentation runs {missing} with ros2 run, not in {lib}'


def test_installed_driver_publishes_from_the_installed_simulated_meter(install):
    """
    As `ros2 run` would: the installed driver with the installed simulated meter publishes.

    ros2 run tskf_ros power_meter_driver --ros-args -p backend:=<share>/config/pm100_sim.yaml@sim
    """
    import signal

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Illuminance

    from tskf_ros.tools.demo_collector import wait_for

    sim_yaml = install / PACKAGE / 'share' / PACKAGE / 'config' / 'pm100_sim.yaml'
    exe = install / PACKAGE / 'lib' / PACKAGE / 'power_meter_driver'
    assert sim_yaml.is_file() and exe.is_file()
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('listener', context=context)
    got = []
    node.create_subscription(Illuminance, 'received_power', got.append,
                             qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    proc = subprocess.Popen(
        ['bash', '-c', 'source "$0/setup.bash" && exec "$@"', str(install), str(exe),
         '--ros-args', '-p', f'backend:={sim_yaml}@sim', '-p', 'rate:=20.0'],
        env=build_env(install.parent), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)
    try:
        wait_for(executor, lambda: len(got) >= 3 or proc.poll() is not None,
                 'readings from the installed driver', 120.0)
    finally:
        proc.send_signal(signal.SIGINT)
        out = proc.communicate(timeout=120)[0]
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    assert len(got) >= 3, out
    # 0.24804 W, the simulated meter's default reading, in mW
    assert all(abs(m.illuminance - 248.04) < 1e-9 for m in got), out


def test_colcon_test_passes_in_the_workspace(install):
    """
    `colcon test` of the built workspace passes, as a ROS user runs it (no ./run, no .venv).

    Its fast part (-m "not slow", so that this test does not run itself again); the README's
    `./run test` runs everything.  The tests that need the ./run environment skip there,
    saying why, and the launch files are started where launch_ros is installed.  Its output
    goes to <workspace>/colcon_test.log as it comes (unbuffered), and a test that runs
    longer than HANG_DUMP_AFTER s there dumps its threads' stacks into it.
    """
    import xml.etree.ElementTree as ET

    workspace = install.parent
    env = {k: v for k, v in build_env(workspace).items()
           if not k.startswith('PYTEST') and k != 'VIRTUAL_ENV'}
    env.update(PYTHONUNBUFFERED='1', PYTHONFAULTHANDLER='1')
    command = [
        sys.executable, '-m', 'colcon', '--log-base', str(workspace / 'log'), 'test',
        '--base-paths', str(workspace / 'src'),
        '--build-base', str(workspace / 'build'),
        '--install-base', str(workspace / 'install'),
        '--event-handlers', 'console_direct+', '--return-code-on-test-failure',
        # (colcon takes an argument that starts with a space as pytest's, not its own)
        '--pytest-args', ' -m', 'not slow', ' -p', 'no:cacheprovider', ' -rs',
        ' -o', f'faulthandler_timeout={HANG_DUMP_AFTER}']
    log = workspace / 'colcon_test.log'
    returncode = run_in_own_session(command, workspace, env, log, COLCON_TEST_TIMEOUT)
    output = log.read_text(errors='replace')[-20000:]
    # (colcon writes a stand-in report with one error when pytest writes none)
    report = ET.parse(workspace / 'build' / PACKAGE / 'pytest.xml').getroot()
    suite = report if report.tag == 'testsuite' else report.find('testsuite')
    counts = {key: int(suite.get(key, 0)) for key in ('tests', 'failures', 'errors', 'skipped')}
    failed = [case.get('name') for case in suite.iter('testcase')
              if case.find('failure') is not None or case.find('error') is not None]
    assert returncode == 0, f'colcon test exited {returncode}, {counts}, {failed}:\n{output}'
    assert counts['tests'] > 1000, (counts, output)
    assert counts['failures'] == counts['errors'] == 0, (counts, failed, output)
    # every skip says why
    for case in suite.iter('testcase'):
        for skipped in case.iter('skipped'):
            assert (skipped.get('message') or '').strip(), (case.get('name'), output)
