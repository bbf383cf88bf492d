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

"""Progress bars (tqdm, on stderr, only on a terminal) and Ctrl-C caught in any phase."""

import signal
import sys
import threading
from types import FrameType, TracebackType
from typing import Callable, Generator, Iterable, Optional, TypeVar

from tqdm import tqdm

__all__ = ['bar', 'DeferredInterrupt', 'Interrupts', 'wrap']

T = TypeVar('T')
S = TypeVar('S', bound='_SigintContext')

# tqdm's default lock holds a multiprocessing RLock, a named semaphore made at the first
# bar (a disabled one too), for bars of forked processes; these bars are each process's
# own (a sweep's workers are spawned).  A process stopped without its clean-up (a Dask
# worker its nanny kills after a Ctrl-C) left that semaphore to the resource tracker's
# "leaked semaphore objects" warning: a thread lock instead (tqdm.set_lock)
tqdm.set_lock(threading.RLock())


def bar(total: Optional[int], desc: str, unit: str, enabled: bool = True) -> tqdm:
    """Return a tqdm bar on stderr; off when not wanted or stderr is not a terminal."""
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False,
                dynamic_ncols=True, disable=not (enabled and sys.stderr.isatty()))


def wrap(items: Iterable[T], total: Optional[int], desc: str, unit: str,
         enabled: bool = True, weight: Optional[Callable[[T], int]] = None
         ) -> Generator[T, None, None]:
    """
    Yield items while a bar counts them (closed at the end, on an error or a break).

    weight: the units an item counts for (default 1 each).
    """
    b = bar(total, desc, unit, enabled)
    try:
        for item in items:
            yield item
            b.update(1 if weight is None else weight(item))
    finally:
        b.close()


class _SigintContext:
    """
    A SIGINT handler of its own while active (in the main thread); `check` after a SIGINT.

    Subclasses define `_handler`.  In another thread nothing is installed and `check`
    never raises.  The previous handler is restored on the way out.
    """

    def __init__(self) -> None:
        self.seen = False
        self._previous: object = None

    def _handler(self, signum: int, frame: Optional[FrameType]) -> None:
        raise NotImplementedError

    def __enter__(self: S) -> S:
        """Install the handler (the main thread only)."""
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, kind: Optional[type], exc: Optional[BaseException],
                 tb: Optional[TracebackType]) -> None:
        """Restore the previous handler."""
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def check(self) -> None:
        """Raise KeyboardInterrupt if a SIGINT came (whatever became of its exception)."""
        if self.seen:
            raise KeyboardInterrupt


class Interrupts(_SigintContext):
    """
    Notice a SIGINT even when a library turns its KeyboardInterrupt into another error.

    While active (in the main thread), SIGINT sets `seen` and raises KeyboardInterrupt as
    Python's default handler does.  A C extension that calls back into Python (rclpy's
    deserialize_message) may swallow that KeyboardInterrupt and raise its own error
    (RuntimeError: "does not deserialize"); `seen` still says that the cause was Ctrl-C.
    """

    def _handler(self, signum: int, frame: Optional[FrameType]) -> None:
        self.seen = True
        raise KeyboardInterrupt


class DeferredInterrupt(_SigintContext):
    """
    Ctrl-C taken at a safe point: SIGINT sets `seen`, and `check()` raises KeyboardInterrupt.

    While active (in the main thread), the first SIGINT raises nothing where it lands: a
    KeyboardInterrupt raised inside a lock's acquire or release, an import, or a compiled
    kernel's dispatch can leave a lock held (the next acquire then waits forever) or turn
    into another error.  The work calls `check()` between its steps (each few thousand
    messages), where nothing is held.  A second SIGINT raises at once (a step that does not
    end).  The previous handler is restored on the way out.
    """

    def _handler(self, signum: int, frame: Optional[FrameType]) -> None:
        if self.seen:
            raise KeyboardInterrupt
        self.seen = True
