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

"""The README's quickstart, line by line as it stands, in a fresh clone of this repository."""

import os
from pathlib import Path
import re
import shutil
import subprocess

import pytest

REPO = Path(__file__).resolve().parents[2]
STATUS = '[quickstart] exit status '


def quickstart_blocks(readme: str) -> list:
    """Return the bash blocks of the README's Quickstart section, each a list of lines."""
    section = readme.split('\n## Quickstart\n', 1)[1].split('\n## ', 1)[0]
    return [block.strip().splitlines()
            for block in re.findall(r'```bash\n(.*?)```', section, re.S)]


def test_the_quickstart_is_one_shell_then_commands():
    blocks = quickstart_blocks((REPO / 'README.md').read_text())
    assert blocks, 'the README has no bash block under ## Quickstart'
    for lines in blocks:
        assert lines[0] == './run shell', lines
        assert len(lines) > 1


@pytest.mark.slow
def test_the_quickstart_works_pasted_into_a_fresh_clone(tmp_path):
    if not (REPO / '.git').exists():
        pytest.skip('not a git checkout: no clone to make')
    # the venv of this checkout, copied, so that the test needs no download; ./run installs
    # the clone into it (the package stamp is removed) as on a first run
    venv = Path(os.environ.get('VIRTUAL_ENV') or REPO / '.venv')
    if not (venv / '.requirements.sha256').is_file():
        pytest.skip(f'needs the venv that ./run makes (none at {venv}: a ROS workspace or '
                    'another venv), to copy into the clone; run it with ./run test')
    clone = tmp_path / 'clone'
    subprocess.run(['git', 'clone', '--quiet', str(REPO), str(clone)], check=True,
                   timeout=120)
    shutil.copytree(venv, clone / '.venv', symlinks=True)
    for stale in ('.package.sha256', 'pip.log'):
        (clone / '.venv' / stale).unlink(missing_ok=True)
    env = {k: v for k, v in os.environ.items()
           if k not in ('VIRTUAL_ENV', 'PYTHONPATH') and not k.startswith('PYTEST')}
    env['PATH'] = os.pathsep.join(p for p in env['PATH'].split(os.pathsep)
                                  if not p.startswith(str(venv)))
    env['HOME'] = str(tmp_path)      # no ~/.bashrc of the machine's user
    for lines in quickstart_blocks((REPO / 'README.md').read_text()):
        # the commands as typed into the shell that ./run shell opens, each followed by a
        # line that reports its exit status
        typed = ''.join(f'{line}\necho "{STATUS}$?"\n' for line in lines[1:])
        proc = subprocess.run(lines[0], shell=True, cwd=clone, env=env, input=typed,
                              text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              timeout=900)
        assert proc.returncode == 0, proc.stdout
        statuses = re.findall(re.escape(STATUS) + r'(\d+)', proc.stdout)
        assert statuses == ['0'] * (len(lines) - 1), proc.stdout
    pngs = sorted(p.name for p in (clone / 'results' / 'plots').glob('*.png'))
    assert pngs, 'the quickstart made no plot'
