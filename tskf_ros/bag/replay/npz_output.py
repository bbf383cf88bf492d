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
"""replay_offline --npz: the estimator's arrays streamed into a .npz, whole or not at all."""

import os
from pathlib import Path
import shutil
import time
from typing import Callable, Optional, Union

from tskf_ros.bag.outputs import check_outputs
from tskf_ros.bag.partials import remove_stale, work_dir
from tskf_ros.bag.progress import DeferredInterrupt
from tskf_ros.bag.replay.adapters import AnyConfig
from tskf_ros.bag.replay.columns import FileStore
from tskf_ros.bag.replay.loop import array_sink, prepare, run_replay
from tskf_ros.bag.replay.sinks import ReplayResult
from tskf_ros.bag.writer import BagExistsError, BagWriteError

__all__ = ['replay_npz']

PathLike = Union[str, os.PathLike]


def _quiet(line: str) -> None:
    """Log nothing."""


def replay_npz(bag: PathLike, path: PathLike,
               config: Union[AnyConfig, PathLike, None] = None, *, overwrite: bool = False,
               topic: Optional[str] = None, input_topic: Optional[str] = None,
               diagnostics: bool = True, log: Callable[[str], None] = _quiet,
               smooth: bool = False, progress: bool = False) -> ReplayResult:
    """
    Run the estimator over `bag` and write replay_arrays' arrays to the .npz file `path`.

    The rows go to raw column files in a hidden work directory next to `path`
    (partials.work_dir) a block at a time, and are then streamed into the .npz there
    (columns.FileStore), which is renamed into place: the memory held does not grow with
    the bag (but for the few diagnostics rows and, with smooth, the smoother's run), and
    an interrupted run leaves nothing under `path` (a SIGKILLed one leaves the work
    directory, which the next run deletes).  Ctrl-C stops it between two blocks of
    messages (DeferredInterrupt).  Raises as replay_arrays, and BagExistsError if `path`
    exists and not overwrite.
    """
    t0 = time.perf_counter()
    path = Path(path)
    check_outputs([path], [bag])
    if path.is_dir() or path.is_symlink() and not path.exists():
        raise BagWriteError(f'{path}: not a file name for the arrays')
    if path.exists() and not overwrite:
        raise BagExistsError(f'{path}: exists already, not overwriting (use --overwrite)')
    with DeferredInterrupt() as interrupt:
        reader, est, result = prepare(bag, config, topic, 'estimator', input_topic, log)
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale(path, log)
        folder = work_dir(path)
        try:
            store = FileStore(folder)
            try:
                sink = array_sink(reader, est, result, smooth, store)
                result.damage = run_replay(reader, est, sink, result, diagnostics, progress,
                                           interrupt.check)
                sink.flush()
                interrupt.check()
                store.write_npz(folder / path.name, sink.extras(result))
            finally:
                store.close()
            interrupt.check()       # the last moment a Ctrl-C leaves nothing
            os.replace(folder / path.name, path)
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    result.seconds = time.perf_counter() - t0
    return result
