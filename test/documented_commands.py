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

"""The commands the README and doc/ name: tskf_NAME in the venv, NAME for `ros2 run`."""

from pathlib import Path
import re

from entry_points import console_scripts

REPO_ROOT = Path(__file__).resolve().parent.parent
README = REPO_ROOT / 'README.md'
PREFIX = 'tskf_'
ROS2_RUN = re.compile(r'ros2 run tskf_ros (\w+)')
# anywhere in a command: tskf_NAME (tskf_ros and tskf_ros_* are the package's own names,
# not executables), python -m MODULE,
# python bench/SCRIPT.py
PREFIXED = re.compile(r'\btskf_(\w+)')
MODULE = re.compile(r'\bpython3? -m (tskf_ros(?:\.\w+)+)(?![.\w<])')
BENCH = re.compile(r'\bpython3? (bench/\w+\.py)')


def readme_commands(text: str) -> list:
    """
    Return the commands of a README: the lines of its bash blocks and its inline code spans.

    Comments and blank lines are left out; each command is its text, stripped.
    """
    commands = []
    for block in re.findall(r'```bash\n(.*?)```', text, flags=re.S):
        commands += [line.strip() for line in block.splitlines()
                     if line.strip() and not line.strip().startswith('#')]
    outside = re.sub(r'```.*?```', '', text, flags=re.S)
    commands += [span.strip() for span in re.findall(r'`([^`\n]+)`', outside)]
    return commands


def named(commands: list) -> tuple:
    """Split commands into (tskf_ names, ros2 run names, bare executable names with args)."""
    scripts = set(console_scripts())
    prefixed, ros2_run, bare = set(), set(), set()
    for command in commands:
        ros2_run.update(ROS2_RUN.findall(command))
        first, _, rest = command.partition(' ')
        if first.startswith(PREFIX) and first[len(PREFIX):] in scripts:
            prefixed.add(first)
        elif first in scripts and rest:
            bare.add(first)
    return prefixed, ros2_run, bare


def documentation() -> dict:
    """Return {path relative to the repository: text} of every markdown page users read."""
    paths = [README, REPO_ROOT / 'bags' / 'README.md']
    for top in ('doc', 'docs'):       # doc/figures is a link to docs: read once, as docs
        paths += sorted(path for path in (REPO_ROOT / top).rglob('*.md')
                        if '_build' not in path.parts)
    return {str(path.relative_to(REPO_ROOT)): path.read_text()
            for path in paths if path.is_file()}


def placeholder(name: str) -> bool:
    """Return whether a command name is a placeholder such as NAME, not a name."""
    return name.isupper()


def wrong_names(text: str) -> list:
    """Return the executables, modules and scripts a page's commands name that do not exist."""
    scripts = set(console_scripts())
    wrong = []
    for command in readme_commands(text):
        for name in PREFIXED.findall(command) + ROS2_RUN.findall(command):
            if name.split('_')[0] != 'ros' and not placeholder(name) and name not in scripts:
                wrong.append(f'{name} in {command!r}')
        for module in MODULE.findall(command):
            path = REPO_ROOT.joinpath(*module.split('.'))
            if not (path.with_suffix('.py').is_file() or (path / '__main__.py').is_file()):
                wrong.append(f'module {module} in {command!r}')
        for script in BENCH.findall(command):
            if not (REPO_ROOT / script).is_file():
                wrong.append(f'script {script} in {command!r}')
    return wrong
