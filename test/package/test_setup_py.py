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

"""setup.py's build of the package: the nodes' kernels compiled ahead of time, or one line."""

import os
from pathlib import Path
import subprocess
import sys

REPO = Path(__file__).resolve().parents[2]


def build_py(tmp_path, env: dict) -> tuple[str, Path]:
    """
    Run setup.py's build_py step, the first of `colcon build`'s, into tmp_path: it succeeds.

    Return its one line 'tskf_ros: ...' (on stderr, which colcon shows: no module was built)
    and the built package's core/.
    """
    result = subprocess.run(
        [sys.executable, 'setup.py', '-q', 'build_py', '--build-lib', str(tmp_path / 'lib')],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    ours = [line for line in (result.stdout + result.stderr).splitlines()
            if line.startswith('tskf_ros:')]
    assert len(ours) == 1, result.stdout + result.stderr
    assert ours[0] in result.stderr.splitlines(), result.stdout + result.stderr
    core = tmp_path / 'lib' / 'tskf_ros' / 'core'
    assert (core / 'aot.py').is_file()
    assert not list(core.glob('**/tskf_kernels_*'))
    return ours[0], core


def test_a_build_without_numba_succeeds_and_says_so_in_one_line(tmp_path):
    hidden = tmp_path / 'hide' / 'numba'
    hidden.mkdir(parents=True)
    (hidden / '__init__.py').write_text("raise ImportError(\"No module named 'numba'\")\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(hidden.parent)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    line, _ = build_py(tmp_path, env)
    assert line.startswith('tskf_ros: numba is not installed'), line
    assert 'in the background' in line
    # the line the installation page shows
    assert line in (REPO / 'doc' / 'installation.md').read_text().splitlines()


def test_a_build_with_the_switch_off_says_so_in_one_line(tmp_path):
    line, _ = build_py(tmp_path, dict(os.environ, TSKF_AOT='off'))
    assert line.startswith('tskf_ros: TSKF_AOT=off: not compiled ahead of time'), line
