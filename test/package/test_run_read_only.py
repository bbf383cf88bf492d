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
`./run` in a read-only tree: what it would write is skipped with one line, the task runs.

The tree is made read-only by a read-only bind mount of it onto itself in a mount
namespace of the test's own (`unshare`; as root, or through a user namespace), so the
checkout itself is untouched.  Before: `./run shell` ended at its first `ln -sfn`.
"""

import os
from pathlib import Path
import shutil
import subprocess

import pytest

REPO = Path(__file__).resolve().parents[2]
VENV = REPO / '.venv'
TIMEOUT = 300.0     # s: ./run's own start (the venv checks, the kernels from numba's cache)
# run the arguments in a private mount namespace where REPO is mounted read-only
READ_ONLY = ('mount --bind -o ro "$0" "$0" && cd "$0" && exec "$@"')

needs_venv = pytest.mark.skipif(
    not (VENV / '.requirements.sha256').is_file(),
    reason='needs the venv that ./run makes in this tree (a ROS workspace has none); run '
           'it with ./run test')


def unshare_prefix() -> list:
    """Return the unshare command that can mount here, or skip."""
    if shutil.which('unshare') is None:
        pytest.skip('no unshare (util-linux)')
    for prefix in (['unshare', '-m', '--propagation', 'private'],
                   ['unshare', '-r', '-m', '--propagation', 'private']):
        probe = subprocess.run([*prefix, 'sh', '-c', READ_ONLY, str(REPO), 'true'],
                               capture_output=True, timeout=TIMEOUT)
        if probe.returncode == 0:
            return prefix
    pytest.skip('cannot mount in a namespace of our own (no privilege, no user namespaces)')


def run_read_only(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*unshare_prefix(), 'sh', '-c', READ_ONLY, str(REPO), './run',
                           *args], capture_output=True, text=True, timeout=TIMEOUT,
                          env=dict(os.environ), stdin=subprocess.DEVNULL)


@needs_venv
def test_run_shell_works_in_a_read_only_tree():
    proc = run_read_only('shell', '-c', 'touch .probe 2>/dev/null || echo read-only; '
                         'command -v tskf_play >/dev/null && echo shell-ok')
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split()[-2:] == ['read-only', 'shell-ok'], proc.stdout
    assert 'Read-only file system' not in proc.stderr and 'error' not in proc.stderr, \
        proc.stderr


@needs_venv
def test_the_links_are_made_and_pruned_where_the_tree_is_writable(tmp_path):
    # the normal path is unchanged: a missing link is made, a dangling one removed
    play, gone = VENV / 'bin' / 'tskf_play', VENV / 'bin' / 'tskf_gone'
    target = os.readlink(play)
    play.unlink()
    gone.symlink_to('../lib/tskf_ros/gone')
    try:
        proc = subprocess.run([str(REPO / 'run'), 'shell', '-c', 'true'], cwd=tmp_path,
                              capture_output=True, text=True, timeout=TIMEOUT,
                              env=dict(os.environ), stdin=subprocess.DEVNULL)
        assert proc.returncode == 0, proc.stderr
        assert os.readlink(play) == target and not os.path.lexists(gone)
    finally:
        if not os.path.lexists(play):
            play.symlink_to(target)
        if os.path.lexists(gone):
            gone.unlink()
