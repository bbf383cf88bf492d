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
The optional tiers: tier 1 runs without them, each optional feature fails in one line.

Each check runs in a subprocess whose imports of the optional libraries fail, as they do
where they are not installed: a finder first on sys.meta_path raises ModuleNotFoundError
for them (the venv has them all installed).
"""

import ast
from pathlib import Path
import subprocess
import sys

import pytest

from tskf_ros.core.optional_dependencies import (EXIT_MISSING_DEPENDENCY, extra_of, EXTRAS,
                                                 MissingDependency, require)

REPO = Path(__file__).resolve().parents[2]
OPTIONAL = sorted({m for extra in EXTRAS.values() for m in extra.modules})
# makes every import of the listed top-level modules fail, as for a library not installed
BLOCKER = """
import importlib.abc, sys
class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in BLOCKED:
            raise ModuleNotFoundError(f'No module named {name!r}', name=name)
        return None
BLOCKED = set(sys.argv[1].split(','))
for name in [m for m in sys.modules if m.split('.')[0] in BLOCKED]:
    del sys.modules[name]
sys.meta_path.insert(0, Blocker())
"""
# tier 1: every module of these must import with no optional library
TIER_ONE = ['tskf_ros.nodes.timescale_estimator', 'tskf_ros.nodes.power_meter_simulator',
            'tskf_ros.nodes.led_link_simulator', 'tskf_ros.nodes.alignment',
            'tskf_ros.bag.player', 'tskf_ros.bag.recorder', 'tskf_ros.bag.replay.cli',
            'tskf_ros.bag.reindex', 'tskf_ros.experiments.reproduce',
            'tskf_ros.experiments.fit_noise', 'tskf_ros.experiments.sweep',
            'tskf_ros.tools.plot_bag', 'tskf_ros.tools.sample_bags']
TIMEOUT = 120.0


def blocked_python(code: str, blocked: list, *args: str) -> subprocess.CompletedProcess:
    """Run code in a Python whose imports of `blocked` fail; return what it did."""
    return subprocess.run([sys.executable, '-c', BLOCKER + code, ','.join(blocked), *args],
                          capture_output=True, text=True, timeout=TIMEOUT, cwd=REPO)


def test_the_blocker_makes_an_import_fail():
    done = blocked_python('import foxglove', ['foxglove'])
    assert done.returncode == 1
    assert "ModuleNotFoundError: No module named 'foxglove'" in done.stderr


def test_tier_one_imports_without_any_optional_library():
    code = ('import importlib\nfor m in sys.argv[2:]:\n    importlib.import_module(m)\n'
            'print(sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED))')
    done = blocked_python(code, OPTIONAL, *TIER_ONE)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == '[]'


def test_no_optional_library_is_imported_at_module_level_of_tier_one():
    # the source itself: an optional import sits in a function (or the tool is optional)
    optional_tools = {'foxglove_bridge.py', 'power_meter.py', 'power_meter_driver.py',
                      'power_meter_interface.py'}
    for path in sorted((REPO / 'tskf_ros').rglob('*.py')):
        if path.name in optional_tools:
            continue
        for node in ast.parse(path.read_text()).body:
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) else [])
            assert not [n for n in names if extra_of(n)], path


def run_tool(tool: str, blocked: list, *argv: str) -> subprocess.CompletedProcess:
    code = (f'sys.argv = [{tool!r}] + sys.argv[2:]\n'
            f'from tskf_ros.tools.console import {tool}\n{tool}()')
    return blocked_python(code, blocked, *argv)


@pytest.mark.parametrize('tool, extra, argv', [
    ('foxglove_bridge', 'foxglove', []),
    ('power_meter_driver', 'visa', []),
    ('sweep', 'analysis', ['--workers', '1', '--out', 'never.csv', '--bags', 'bags']),
])
def test_an_optional_tool_without_its_library_says_so_in_one_line(tool, extra, argv, tmp_path):
    done = run_tool(tool, list(EXTRAS[extra].modules), *argv)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == EXIT_MISSING_DEPENDENCY, done.stderr
    assert len(lines) == 1 and 'Traceback' not in done.stderr, done.stderr
    assert f'pip install {" ".join(map(repr, EXTRAS[extra].requirements))}' in lines[0]
    assert f'tskf_ros[{extra}]' in lines[0]
    assert all(key in lines[0] for key in EXTRAS[extra].rosdep_keys)
    assert not (REPO / 'never.csv').exists()


def test_sweep_without_dask_runs_in_process(tmp_path):
    # --workers 0 needs no Dask: the usage line about the missing bags, not about Dask
    done = run_tool('sweep', ['dask', 'distributed'], '--workers', '0', '--out',
                    str(tmp_path / 't.csv'), '--bags', str(tmp_path / 'none'))
    assert done.returncode == 1 and done.stderr.startswith('sweep: error: no bags found in')


def test_require_passes_other_import_errors_on():
    assert require('json').dumps(1) == '1'
    with pytest.raises(ModuleNotFoundError) as info:
        require('no_such_module_of_any_extra')
    assert not isinstance(info.value, MissingDependency)


def test_a_missing_optional_module_is_a_missing_dependency():
    done = blocked_python(
        'from tskf_ros.core.optional_dependencies import require\n'
        'try:\n    require("pyvisa", "the driver")\n'
        'except ImportError as exc:\n    print(type(exc).__name__, exc)', ['pyvisa'])
    assert done.stdout.startswith('MissingDependency the driver needs pyvisa'), done.stderr
    assert issubclass(MissingDependency, ImportError)


def test_extras_match_setup_py():
    tree = ast.parse((REPO / 'setup.py').read_text())
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, 'id', '') == 'setup')
    extras = ast.literal_eval(next(k.value for k in call.keywords
                                   if k.arg == 'extras_require'))
    assert extras == {name: list(e.requirements) for name, e in EXTRAS.items()}


def test_the_docs_list_every_extra_and_its_keys():
    doc = (REPO / 'doc' / 'installation.md').read_text()
    for extra in EXTRAS.values():
        assert f'extra `{extra.name}`' in doc
        assert all(f'`{key}`' in doc for key in extra.rosdep_keys), extra.name
