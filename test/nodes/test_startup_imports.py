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
import subprocess
import sys

import pytest

# what no node imports to start: slow or heavy, and used elsewhere (numba: in the
# background, once the first kernel has run)
NEVER = ('scipy.stats', 'scipy.integrate', 'scipy.optimize', 'matplotlib', 'dask', 'numba',
         'mcap', 'rosbags', 'tskf_ros.experiments', 'tskf_ros.bag.reader',
         'tskf_ros.tools.plot_bag')
# the estimator's path has no LED code, and no scipy beyond its package (numpy's linalg)
ESTIMATOR_NEVER = NEVER + ('tskf_ros.led', 'scipy.linalg', 'scipy.special', 'scipy.sparse')


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
    ('tskf_ros.nodes.alignment', NEVER),
])
def test_a_node_module_imports_only_its_path(module, never):
    assert _offending(_imported(module), never) == []


def test_the_alignment_configuration_needs_no_scipy_optimize():
    # the default configuration (the intensity fit's peak and zone width) at start
    then = 'from tskf_ros.led.alignment_config import AlignmentConfig; AlignmentConfig()'
    assert _offending(_imported('tskf_ros.nodes.alignment', then), NEVER) == []


def test_the_check_sees_a_forbidden_module():
    assert _offending({'scipy.stats._stats_py', 'scipy'}, ('scipy.stats',)) == \
        ['scipy.stats._stats_py']
