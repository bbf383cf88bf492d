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
The hidden work directory of an output that can be made again, and what a killed run left.

An output of replay_offline is written in `.<name>.partial-pid<PID>-XXXX` next to it and
renamed into place when whole.  Ctrl-C deletes that directory; a SIGKILL (or a power cut)
cannot, so the next run writing the same output deletes every such directory whose
process is gone.  (The recorder's `.<name>.partial-XXXX` directories hold a recording that
exists nowhere else: they carry no PID, are never deleted here, and `reindex` recovers them.)
"""

import os
from pathlib import Path
import re
import shutil
import tempfile
from typing import Callable, Optional

__all__ = ['remove_stale', 'work_dir']

_PID = re.compile(r'\.partial-pid(\d+)-[^/]+$')


def work_dir(path: Path) -> Path:
    """Make and return the hidden work directory of the output `path` (next to it)."""
    return Path(tempfile.mkdtemp(prefix=f'.{path.name}.partial-pid{os.getpid()}-',
                                 dir=path.parent))


def _alive(pid: int) -> bool:
    """Say whether a process `pid` exists (one of another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale(path: Path, log: Optional[Callable[[str], None]] = None) -> list[Path]:
    """Delete the work directories of `path` whose process is gone; return them."""
    removed = []
    parent = path.parent
    if not parent.is_dir():
        return removed
    prefix = f'.{path.name}.partial-pid'
    for entry in parent.iterdir():
        if not entry.name.startswith(prefix) or entry.is_symlink() or not entry.is_dir():
            continue
        match = _PID.search(entry.name)
        if match is None or int(match.group(1)) == os.getpid() or _alive(int(match.group(1))):
            continue
        shutil.rmtree(entry, ignore_errors=True)
        removed.append(entry)
        if log is not None:
            log(f'deleted {entry}, left by an interrupted run (process {match.group(1)} '
                'is gone)')
    return removed
