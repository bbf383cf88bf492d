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
"""The modules a node's start imports: only what its path runs (start-up time, memory)."""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

# what no node imports to start: slow or heavy, and used elsewhere (numba: in the
# background, once the first kernel has run)
NEVER = ('scipy.stats', 'scipy.integrate', 'scipy.optimize', 'matplotlib', 'dask', 'numba',
         'mcap', 'rosbags', 'tskf_ros.experiments', 'tskf_ros.bag.reader',
         'tskf_ros.tools.plot_bag', 'numpy.random')
# imported only when a start needs them: argparse for a non-ROS argument (--help,
# --executor), difflib for a parameter the node does not have, rclpy.experimental for
# --executor events
ON_DEMAND = ('argparse', 'difflib', 'rclpy.experimental')
# the estimator's path has no LED code, and no scipy beyond its package (numpy's linalg);
# the fixed-lag smoother only with smoothing_lag > 0
ESTIMATOR_NEVER = NEVER + ON_DEMAND + ('tskf_ros.led', 'scipy.linalg', 'scipy.special',
                                       'scipy.sparse', 'tskf_ros.owc.lagged_estimates',
                                       'tskf_ros.core.fixed_lag', 'tskf_ros.core.smoother')
# the alignment node's one-axis start (axes 1, the default): no two-axis module, and no
# geometry_msgs (the estimator's input type)
ALIGNMENT_NEVER = NEVER + ON_DEMAND + ('tskf_ros.led.two_axis', 'tskf_ros.led.pan_tilt_stream',
                                       'tskf_ros.messages.pan_tilt_interface', 'geometry_msgs')


def _imported(module: str, then: str = 'pass') -> set[str]:
    code = f'import sys, {module}; {then}; print("\\n".join(sys.modules))'
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            env=dict(os.environ), timeout=300)
    assert result.returncode == 0, result.stderr
    return set(result.stdout.split())


def _offending(modules: set[str], never: tuple) -> list[str]:
    return sorted(m for m in modules if any(m == n or m.startswith(n + '.') for n in never))


@pytest.mark.parametrize('module, never', [
    ('tskf_ros.nodes.timescale_estimator', ESTIMATOR_NEVER),
    # what the console script `timescale_estimator` imports before main()
    ('tskf_ros.tools.console, tskf_ros.nodes.timescale_estimator', ESTIMATOR_NEVER),
    ('tskf_ros.nodes.alignment', ALIGNMENT_NEVER),
])
def test_a_node_module_imports_only_its_path(module, never):
    assert _offending(_imported(module), never) == []


def test_the_alignment_configuration_needs_no_scipy_optimize():
    # the default configuration (the intensity fit's peak and zone width) at start
    then = 'from tskf_ros.led.alignment_config import AlignmentConfig; AlignmentConfig()'
    assert _offending(_imported('tskf_ros.nodes.alignment', then), ALIGNMENT_NEVER) == []


# a node built as its console script builds it, then handed inputs through its subscription's
# callback: stamps every `period` s (the node's default nominal period), one gap of two
# periods (the estimator's sampling-interval check runs on each new interval)
RUN_NODE = """
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import Illuminance
from tskf_ros.core import jit
from {module} import {cls}
jit.set_mode('background')
rclpy.init()
node = {cls}(parameter_overrides=[Parameter(k, value=v) for k, v in {parameters!r}.items()])
msg = Illuminance()
t = 1000.0
for k in range(40):
    t += {period} * (2 if k == 20 else 1)
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int((t - int(t)) * 1e9)
    msg.illuminance = 1.0 + 0.01 * k
    node.sub.callback(msg)
node.destroy_node()
rclpy.try_shutdown()
"""


@pytest.mark.parametrize('module, cls, period, parameters, never', [
    ('tskf_ros.nodes.timescale_estimator', 'TimescaleEstimator', 1.0, {}, ESTIMATOR_NEVER),
    ('tskf_ros.nodes.alignment', 'Alignment', 0.05, {}, ALIGNMENT_NEVER),
    # two axes, the supervised conical-scan EKF: its kernels are in the compiled module too
    ('tskf_ros.nodes.alignment', 'Alignment', 0.05, {'axes': 2, 'pat.enabled': True},
     NEVER + ON_DEMAND + ('geometry_msgs',)),
], ids=['estimator', 'alignment', 'alignment_two_axes'])
def test_a_node_built_and_fed_imports_no_scipy(module, cls, period, parameters, never):
    # neither node's start nor its first inputs import scipy (the lock detector's NIS band
    # is tskf_ros.core.chi_square's, the interval check's eigenvalues numpy's), numba or
    # anything in NEVER
    from tskf_ros.core import aot
    if aot.load() is None:      # e.g. a colcon workspace's source copy, built without it
        pytest.skip('the kernels are not compiled ahead of time for this tree: a node '
                    'runs numba in the background (python -m tskf_ros.core.aot builds them)')
    then = RUN_NODE.format(module=module, cls=cls, period=period, parameters=parameters)
    modules = _imported(module, then=f'exec({then!r})')
    assert _offending(modules, never + ('scipy',)) == []


def _console_script(name: str):
    """Return the installed console script `name` (./run's link, else <prefix>/lib/tskf_ros)."""
    script = shutil.which(f'tskf_{name}') or Path(sys.prefix) / 'lib' / 'tskf_ros' / name
    return script if Path(script).is_file() else None


# runs a script as its shebang's interpreter would, with --help, and writes the modules
# it imported into a file at the exit (importlib.import_module's imports, the console
# runner's, are not in `python -X importtime`)
RUN_SCRIPT = """
import atexit, runpy, sys
script, out = sys.argv[1:3]
def written():
    with open(out, 'w') as f:
        f.write('\\n'.join(sys.modules))
atexit.register(written)
sys.argv = [script, '--help']
runpy.run_path(script, run_name='__main__')
"""


@pytest.mark.parametrize('name', ['timescale_estimator', 'alignment'])
def test_the_console_script_imports_its_node_directly(name, tmp_path):
    # setuptools' own scripts look the function up through importlib.metadata at every
    # start (setup.py rewrites them): the script as installed, run to its --help, which
    # comes after the node's module is imported
    script = _console_script(name)
    if script is None:
        pytest.skip(f'no console script {name} installed for this interpreter')
    out = tmp_path / 'modules.txt'
    result = subprocess.run([sys.executable, '-c', RUN_SCRIPT, str(script), str(out)],
                            capture_output=True, text=True, env=dict(os.environ), timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert 'usage:' in result.stdout
    imported = set(out.read_text().split())
    assert f'tskf_ros.nodes.{name}' in imported
    assert _offending(imported, ('importlib.metadata', 'pkg_resources')) == []


def test_the_check_sees_a_forbidden_module():
    assert _offending({'scipy.stats._stats_py', 'scipy'}, ('scipy.stats',)) == \
        ['scipy.stats._stats_py']
