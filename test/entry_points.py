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

"""What the tests read from setup.py: the executables (console_scripts) it declares."""

import ast
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


def console_scripts():
    """Return the executable names declared in setup.py's console_scripts entry points."""
    tree = ast.parse((REPO_ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'entry_points':
            specs = ast.literal_eval(node.value).get('console_scripts', [])
            return [spec.split('=', 1)[0].strip() for spec in specs]
    return []


def console_script_targets():
    """Return {executable name: 'module:function'} of setup.py's console_scripts."""
    tree = ast.parse((REPO_ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'entry_points':
            specs = ast.literal_eval(node.value).get('console_scripts', [])
            return {name.strip(): target.strip()
                    for name, _, target in (spec.partition('=') for spec in specs)}
    return {}
