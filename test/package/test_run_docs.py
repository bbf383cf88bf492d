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
"""`./run docs` twice at once: the second waits for the first instead of breaking its build."""

import fcntl
import os
from pathlib import Path
import shutil
import subprocess
import time

import pytest

REPO = Path(__file__).resolve().parent.parent.parent
TIMEOUT = 120.0     # s: ./run's own start (the venv checks, the kernels from numba's cache)
POLL = 0.05         # s between two looks at a condition (not a synchronisation)


@pytest.mark.skipif(shutil.which('flock') is None, reason='no flock (util-linux)')
@pytest.mark.skipif(not (REPO / '.venv' / '.requirements.sha256').is_file(),
                    reason='needs the venv that ./run makes in this tree (a ROS workspace '
                           'has none, and ./run docs would install one: minutes of pip, '
                           'about 1 GB); run it with ./run test')
def test_a_second_docs_build_waits_for_the_first(tmp_path):
    lock = REPO / 'doc' / '_build' / '.lock'
    lock.parent.mkdir(parents=True, exist_ok=True)
    out = tmp_path / 'out'
    with open(lock, 'w') as held:
        fcntl.flock(held, fcntl.LOCK_EX)       # a first build, running
        with open(out, 'w') as f:
            # --version: Sphinx says its version and ends (no build), once it has the lock
            proc = subprocess.Popen([str(REPO / 'run'), 'docs', '--version'], cwd=tmp_path,
                                    stdout=f, stderr=subprocess.STDOUT,
                                    env=dict(os.environ))
        try:
            deadline = time.monotonic() + TIMEOUT
            while 'waiting for it to end' not in out.read_text():
                assert proc.poll() is None, out.read_text()
                assert time.monotonic() < deadline, out.read_text()
                time.sleep(POLL)
            assert proc.poll() is None and 'sphinx-build' not in out.read_text()
        except BaseException:
            proc.kill()
            proc.wait()
            raise
    # the first build ends: the second goes on
    assert proc.wait(timeout=TIMEOUT) == 0, out.read_text()
    assert 'sphinx-build' in out.read_text()
