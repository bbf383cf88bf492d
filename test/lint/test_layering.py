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
The layers flow one way, read from every module's imports (ast), not from its behaviour.

    core  ->  owc, led (domains)  ->  messages  ->  nodes | bag  ->  experiments, tools
                                                   nodes  ->  testing (the pytest plugin)

A module may import its own folder and the folders of lower layers only; nodes and bag are
siblings and never import each other; core and the domains never import ROS.  A module's
`if __name__ == '__main__':` block (the process entry of `python -m`, outside the layers as
setup.py's console scripts are) may also import ENTRY, the quiet-on-Ctrl-C runner.  Also: no
module name is used twice in the package, and no constant is defined twice.
"""

import ast
from collections import defaultdict
from pathlib import Path
import subprocess
import sys

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
PACKAGE = 'tskf_ros'
# folder -> the folders of tskf_ros it may import (its own included)
ALLOWED = {
    'core': {'core'},
    'owc': {'core', 'owc'},
    'led': {'core', 'led'},
    'messages': {'core', 'owc', 'led', 'messages'},
    'nodes': {'core', 'owc', 'led', 'messages', 'nodes'},
    'bag': {'core', 'owc', 'led', 'messages', 'bag'},
    'experiments': {'core', 'owc', 'led', 'messages', 'nodes', 'bag', 'experiments', 'tools'},
    'tools': {'core', 'owc', 'led', 'messages', 'nodes', 'bag', 'experiments', 'tools'},
    'testing': {'core', 'owc', 'led', 'messages', 'nodes', 'testing'},
}
ROS_FREE = ('core', 'owc', 'led')
# top-level packages that mean ROS: rclpy and the interface packages
ROS_PACKAGES = ('rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosidl_runtime_py')
ENTRY = f'{PACKAGE}.tools.console'


def modules() -> dict:
    """Return {dotted module name: path} for every module of the package."""
    out = {}
    for path in sorted((REPO_ROOT / PACKAGE).rglob('*.py')):
        parts = path.relative_to(REPO_ROOT).with_suffix('').parts
        if parts[-1] == '__init__':
            parts = parts[:-1]
        out['.'.join(parts)] = path
    return out


def is_main_block(node: ast.AST) -> bool:
    """Return whether node is `if __name__ == '__main__':`."""
    test = getattr(node, 'test', None)
    return (isinstance(node, ast.If) and isinstance(test, ast.Compare)
            and isinstance(test.left, ast.Name) and test.left.id == '__name__'
            and len(test.comparators) == 1 and isinstance(test.comparators[0], ast.Constant)
            and test.comparators[0].value == '__main__')


def imported_names(tree: ast.AST, path: Path) -> set:
    """Return the absolute dotted names imported anywhere under tree."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f'{path}: relative import'
            if node.module == PACKAGE:     # `from tskf_ros import led`: tskf_ros.led
                names.update(f'{PACKAGE}.{a.name}' for a in node.names)
            else:
                names.add(node.module)
    return names


def imports(path: Path) -> set:
    """Return the absolute dotted names a module imports, at any depth of its code."""
    tree = ast.parse(path.read_text())
    main_blocks = [node for node in tree.body if is_main_block(node)]
    tree.body = [node for node in tree.body if not is_main_block(node)]
    names = imported_names(tree, path)
    for block in main_blocks:
        names |= imported_names(block, path) - {ENTRY}
    return names


def folder(dotted: str) -> str:
    """Return the subpackage of tskf_ros a dotted name lies in ('' for tskf_ros itself)."""
    parts = dotted.split('.')
    return parts[1] if len(parts) > 1 else ''


def layer_violations(mods: dict) -> list:
    """Return 'module imports name' for every import that goes against ALLOWED."""
    bad = []
    for name, path in mods.items():
        mine = folder(name)
        for imported in imports(path):
            top = imported.split('.')[0]
            if top == PACKAGE:
                target = folder(imported)
                if mine == '' or target not in ALLOWED[mine]:
                    bad.append(f'{name} imports {imported}')
            elif mine in ROS_FREE and (top in ROS_PACKAGES or top.endswith('_msgs')):
                bad.append(f'{name} imports {imported} (ROS) in a ROS-free layer')
    return bad


def test_every_folder_has_a_layer():
    folders = {folder(m) for m in modules()} - {''}
    assert folders == set(ALLOWED)


def test_imports_follow_the_layers():
    assert layer_violations(modules()) == []


def test_the_layer_check_catches_an_upward_import(tmp_path):
    bad = tmp_path / 'x.py'
    bad.write_text('from tskf_ros.nodes import node_base\nimport rclpy\n')
    assert sorted(layer_violations({'tskf_ros.core.x': bad})) == [
        'tskf_ros.core.x imports rclpy (ROS) in a ROS-free layer',
        'tskf_ros.core.x imports tskf_ros.nodes']
    sibling = tmp_path / 'y.py'
    sibling.write_text('from tskf_ros.bag import reader\n')
    assert layer_violations({'tskf_ros.nodes.y': sibling}) == [
        'tskf_ros.nodes.y imports tskf_ros.bag']


def test_only_the_main_block_may_import_the_entry(tmp_path):
    entry = tmp_path / 'z.py'
    entry.write_text("if __name__ == '__main__':\n    from tskf_ros.tools.console import "
                     'run_as_main\n    from tskf_ros.tools import plot_bag\n')
    assert layer_violations({'tskf_ros.core.z': entry}) == [
        'tskf_ros.core.z imports tskf_ros.tools']
    entry.write_text('from tskf_ros.tools.console import run_as_main\n')
    assert layer_violations({'tskf_ros.core.z': entry}) == [
        'tskf_ros.core.z imports tskf_ros.tools.console']


def test_no_module_name_is_used_twice():
    seen = defaultdict(list)
    for name, path in modules().items():
        if path.name != '__init__.py':
            seen[path.stem].append(name)
    assert {k: v for k, v in seen.items() if len(v) > 1} == {}


def test_no_constant_is_defined_twice():
    """An UPPER_CASE module-level name bound to a literal lives in one module only."""
    where = defaultdict(list)
    for name, path in modules().items():
        for node in ast.parse(path.read_text()).body:
            if (isinstance(node, ast.Assign) and len(node.targets) == 1
                    and isinstance(node.targets[0], ast.Name)
                    and node.targets[0].id.isupper()
                    and isinstance(node.value, ast.Constant)):
                where[(node.targets[0].id, repr(node.value.value))].append(name)
    assert {k: v for k, v in where.items() if len(v) > 1} == {}


@pytest.mark.parametrize('layer', ROS_FREE)
def test_ros_free_layers_import_without_rclpy(layer):
    """Really import every module of the layer: nothing it pulls in may load rclpy."""
    names = [m for m in modules() if folder(m) == layer]
    check = '\n'.join(['import sys'] + [f'import {m}' for m in names] + [
        f'leaked = sorted(m for m in sys.modules if m.partition(chr(46))[0] in {ROS_PACKAGES})',
        'assert not leaked, leaked'])
    result = subprocess.run([sys.executable, '-c', check], cwd=REPO_ROOT,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
