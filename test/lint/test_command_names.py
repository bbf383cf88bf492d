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

"""The commands the README and doc/ name exist: tskf_NAME in the venv, NAME for `ros2 run`."""

import os
from pathlib import Path
import sys

from documented_commands import (documentation, named, placeholder, PREFIX, README,
                                 readme_commands, wrong_names)
from entry_points import console_scripts
import pytest


def test_the_documentation_names_only_commands_that_exist():
    pages = documentation()
    assert 'README.md' in pages and 'doc/index.md' in pages, sorted(pages)
    wrong = {path: wrong_names(text) for path, text in pages.items()}
    wrong = {path: names for path, names in wrong.items() if names}
    assert not wrong, f'commands named in the documentation that do not exist: {wrong}'
    bare = {path: sorted(named(readme_commands(text))[2]) for path, text in pages.items()}
    bare = {path: names for path, names in bare.items() if names}
    assert not bare, f'bare executable names (write tskf_NAME in the venv): {bare}'


def test_wrong_names_finds_what_does_not_exist():
    # the check itself, on commands that name a missing executable, module and script
    text = ('```bash\ntskf_no_such_tool x\nros2 run tskf_ros no_such_node\n'
            'python -m tskf_ros.no_such_module\npython bench/no_such_bench.py\n```\n'
            '`tskf_play --help`, `python -m tskf_ros.bag.player`, `tskf_NAME`\n')
    wrong = wrong_names(text)
    assert len(wrong) == 4, wrong
    assert all(name in ' '.join(wrong) for name in (
        'no_such_tool', 'no_such_node', 'tskf_ros.no_such_module', 'bench/no_such_bench.py'))


def test_the_readme_names_its_commands_as_they_are_installed():
    prefixed, ros2_run, bare = named(readme_commands(README.read_text()))
    assert {'tskf_record', 'tskf_play'} <= prefixed
    # a bare name is not on the venv's PATH (play would be SoX's): the README must not use it
    assert not bare, f'the README runs {sorted(bare)} by bare names; write tskf_NAME'
    ros2_run = {name for name in ros2_run if not placeholder(name)}
    assert ros2_run <= set(console_scripts()), sorted(ros2_run - set(console_scripts()))


def test_the_venv_has_every_executable_under_its_prefixed_name_only():
    # ./run links .venv/bin/tskf_NAME to .venv/lib/tskf_ros/NAME (the editable install's
    # script_dir, as colcon's lib/tskf_ros); the generic names stay off the PATH
    bin_dir = Path(sys.prefix) / 'bin'
    lib_dir = Path(sys.prefix) / 'lib' / 'tskf_ros'
    if not (Path(sys.prefix) / '.requirements.sha256').is_file():
        pytest.skip(f'not the venv that ./run makes ({sys.prefix}): a ROS workspace or '
                    'another venv has no tskf_NAME links; run it with ./run test')
    for name in console_scripts():
        exe = bin_dir / f'{PREFIX}{name}'
        assert exe.is_file() and os.access(exe, os.X_OK), \
            f'{exe} is missing (./run makes it; run ./run once)'
        assert exe.resolve() == (lib_dir / name).resolve()
        assert not (bin_dir / name).exists() or name not in ('play', 'record'), \
            f'{bin_dir / name} would shadow other programs'
