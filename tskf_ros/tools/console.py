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

"""The console scripts' and `python -m` entry: run a tool, end quietly (exit 130) on Ctrl-C."""

import _thread
import importlib
import os
import signal
import sys
import threading
from types import FrameType
from typing import Any, Callable, NoReturn, Optional, Sequence, TYPE_CHECKING

from tskf_ros.bag.bag_errors import EXIT_INTERRUPTED

if TYPE_CHECKING:
    import subprocess

# each console script (setup.py's console_scripts) and the function it runs;
# test/tools/test_console.py checks this table against setup.py
TOOLS = {
    'reproduce': 'tskf_ros.experiments.reproduce:main',
    'power_meter_simulator': 'tskf_ros.nodes.power_meter_simulator:main',
    'timescale_estimator': 'tskf_ros.nodes.timescale_estimator:main',
    'record': 'tskf_ros.bag.recorder:console_main',
    'play': 'tskf_ros.bag.player:console_main',
    'replay_offline': 'tskf_ros.bag.replay.cli:console_main',
    'reindex': 'tskf_ros.bag.reindex:console_main',
    'plot_bag': 'tskf_ros.tools.plot_bag:console_main',
    'make_sample_bags': 'tskf_ros.tools.sample_bags:console_main',
    'led_link_simulator': 'tskf_ros.nodes.led_link_simulator:main',
    'alignment': 'tskf_ros.nodes.alignment:main',
    'power_meter_driver': 'tskf_ros.nodes.power_meter_driver:main',
    'fit_noise': 'tskf_ros.experiments.fit_noise:console_main',
    'sweep': 'tskf_ros.experiments.sweep:console_main',
    'foxglove_bridge': 'tskf_ros.tools.foxglove_bridge:main',
}


def run(tool: str) -> NoReturn:
    """
    Import and run one tool (a key of TOOLS); exit with its status.

    A KeyboardInterrupt while its modules import (numpy, rclpy: seconds on a loaded
    machine), while it runs or while it cleans up ends the process with EXIT_INTERRUPTED
    and nothing on stderr; once the tool has ended, Ctrl-C is ignored.  An interrupt that
    lands inside a C extension's import comes out as another error (numpy: an ImportError
    "PyCapsule_Import could not import module"): after a Ctrl-C, any error is the
    interrupt.  A SIGINT before this runs (the interpreter's start, site's imports, the
    import of this module: tens of milliseconds) is Python's own, a traceback, unless the
    process was started by start_held.
    """
    def entry() -> object:
        module, _, name = TOOLS[tool].partition(':')
        return getattr(importlib.import_module(module), name)()
    _quietly(entry, tool)


def run_as_main(main: Callable[[], object]) -> NoReturn:
    """
    Run main as a module's `if __name__ == '__main__':` block does (`python -m`); exit.

    Ctrl-C while main runs or cleans up ends the process as run() does: EXIT_INTERRUPTED,
    no traceback (a tool may print its own one line), and Ctrl-C is ignored once main has
    ended.  Not covered: a Ctrl-C while `python -m` imports the module (its numpy, scipy,
    rclpy), which happens before this is called: Python prints its KeyboardInterrupt
    traceback and dies of SIGINT.  The console scripts (run) cover that phase too, and a
    process started by start_held every phase.
    """
    _quietly(main, main.__module__.rpartition('.')[2])


class SigintFlag:
    """
    Take SIGINT as Python does (KeyboardInterrupt) and remember it; restore() undoes it.

    first (optional) runs in the handler, before the KeyboardInterrupt: before any code
    that the interrupt reaches, in this thread or in one it hands work to.
    """

    def __init__(self, first: Optional[Callable[[], None]] = None) -> None:
        self.event = threading.Event()
        self.first = first
        self.main = threading.current_thread() is threading.main_thread()
        self.previous = signal.signal(signal.SIGINT, self._on_sigint) if self.main else None

    def _on_sigint(self, signum: int, frame: Optional[FrameType]) -> None:
        self.event.set()
        if self.first is not None:
            self.first()
        raise KeyboardInterrupt

    def is_set(self) -> bool:
        """Tell whether a SIGINT came."""
        return self.event.is_set()

    def restore(self) -> None:
        """Put the previous SIGINT handler back (in the main thread)."""
        if self.main:
            signal.signal(signal.SIGINT, self.previous)


class SigintHeld:
    """
    Hold SIGINT over a block (`with SigintHeld() as held:`); `held.came` says if one came.

    For a block a KeyboardInterrupt must not cut short (a Dask cluster starting or
    closing: its processes and semaphores would be left behind).  The calling thread
    blocks SIGINT, and what it starts meanwhile inherits that mask: the threads, and
    the processes those threads start, which then never take a terminal's Ctrl-C (a
    LocalCluster's workers: the sweep stops them).  A SIGINT that reaches another thread
    meanwhile (a BLAS library's own) is noted by a handler that does not raise, and one
    held for this thread is taken at the end; neither raises: the caller acts on `came`.
    Outside the main thread it does nothing.
    """

    def __init__(self) -> None:
        self.came = False
        self.main = threading.current_thread() is threading.main_thread()
        self.mask: set = set()
        self.previous: Any = None

    def __enter__(self) -> 'SigintHeld':
        if self.main:
            self.mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            self.previous = signal.signal(signal.SIGINT, self._note)
        return self

    def _note(self, signum: int, frame: Optional[FrameType]) -> None:
        self.came = True

    def __exit__(self, *exc: object) -> None:
        if self.main:
            if signal.sigtimedwait({signal.SIGINT}, 0) is not None:
                self.came = True
            signal.signal(signal.SIGINT, self.previous)
            signal.pthread_sigmask(signal.SIG_SETMASK, self.mask)


class _SigintSeen:
    """
    Notice every SIGINT of the process, whichever Python handler takes it.

    A tool may install its own SIGINT handler over the wrapper's (fit_noise's reader,
    sweep's Dask loop) and a library may turn the KeyboardInterrupt into another error
    (numba's dispatcher: "SystemError: CPUDispatcher(...) returned a result with an
    exception set"), so the wrapper's own flag may never be set.  Python's C-level handler
    writes the number of every signal that has a Python handler into the wakeup fd
    (signal.set_wakeup_fd), whoever's Python handler then runs: a pipe read once the tool
    has ended tells whether a SIGINT came.  A library that takes the wakeup fd for itself
    leaves the flag of SigintFlag as the only witness.

    A KeyboardInterrupt raised where Python can only report it (a weakref callback, such
    as importlib's `_get_module_lock.<locals>.cb` while modules load: "Exception ignored
    in ...") is swallowed by the interpreter and the Ctrl-C lost; the unraisable hook
    installed here drops that report and delivers the interrupt again, from a helper
    thread (`_thread.interrupt_main`), so that it lands once the callback has returned.
    """

    def __init__(self) -> None:
        self.read_fd, self.write_fd = os.pipe()
        os.set_blocking(self.read_fd, False)
        os.set_blocking(self.write_fd, False)
        self.seen = False
        self.previous_fd = signal.set_wakeup_fd(self.write_fd, warn_on_full_buffer=False)
        self.previous_hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable

    def came(self, flag: SigintFlag) -> bool:
        """Say whether a SIGINT has come: a byte in the wakeup pipe, or the flag set."""
        try:
            while data := os.read(self.read_fd, 512):
                self.seen = self.seen or signal.SIGINT in data
        except (BlockingIOError, OSError):
            pass
        return self.seen or flag.is_set()

    def _unraisable(self, unraisable: Any) -> None:
        if issubclass(unraisable.exc_type, KeyboardInterrupt):
            _thread.start_new_thread(_thread.interrupt_main, ())
            return
        self.previous_hook(unraisable)

    def close(self) -> None:
        """Give the wakeup fd and the unraisable hook back; close the pipe."""
        current = signal.set_wakeup_fd(self.previous_fd)
        if current != self.write_fd:                # a library's own: it keeps it
            signal.set_wakeup_fd(current)
        sys.unraisablehook = self.previous_hook
        os.close(self.read_fd)
        os.close(self.write_fd)


def start_held(cmd: Sequence[str], **popen: Any) -> 'subprocess.Popen[Any]':
    """
    Start cmd, a tool run through run() or run_as_main, with SIGINT held until it can take it.

    A SIGINT before the child's runner has its handler (while the interpreter starts,
    site's .pth files import, this module imports) would end it with Python's
    KeyboardInterrupt traceback or "Fatal Python error: init_import_site".  The child
    starts with SIGINT blocked (a signal mask survives fork and exec, and Popen passes the
    calling thread's on); the runner unblocks it once its handler is in place, and a SIGINT
    that came meanwhile, kept pending by the kernel, is taken then: exit EXIT_INTERRUPTED,
    nothing on stderr.  popen: subprocess.Popen's keyword arguments.
    """
    import subprocess
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return subprocess.Popen(cmd, **popen)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _quietly(entry: Callable[[], object], tool: str) -> NoReturn:
    interrupted = SigintFlag()
    seen = _SigintSeen() if interrupted.main else None
    try:
        if interrupted.main:    # a SIGINT held since the start (start_held) is taken here
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        status = entry()
    except KeyboardInterrupt:
        status = EXIT_INTERRUPTED
    except Exception as exc:  # noqa: B902 - after a Ctrl-C, which it then is
        if interrupted.is_set() or (seen is not None and seen.came(interrupted)):
            status = EXIT_INTERRUPTED
        else:
            status = _missing_dependency(exc, tool)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)    # the exit itself is not interrupted
        if seen is not None:
            seen.close()
    sys.exit(status)


def _missing_dependency(exc: Exception, tool: str) -> int:
    """Print the one line of an optional library not installed; re-raise any other error."""
    if not isinstance(exc, ImportError):
        raise exc
    from tskf_ros.core.optional_dependencies import (EXIT_MISSING_DEPENDENCY, missing,
                                                     MissingDependency)
    error = exc if isinstance(exc, MissingDependency) else (
        missing(exc) if isinstance(exc, ModuleNotFoundError) else None)
    if error is None:
        raise exc
    print(f'{tool}: error: {error}', file=sys.stderr)
    return EXIT_MISSING_DEPENDENCY


def entry_point(tool: str) -> Callable[[], NoReturn]:
    """Return the console-script function of one tool (what setup.py names)."""
    def main() -> NoReturn:
        run(tool)
    main.__name__ = main.__qualname__ = tool
    main.__doc__ = f'Run {tool} (the console script), quiet on Ctrl-C.'
    return main


reproduce = entry_point('reproduce')
power_meter_simulator = entry_point('power_meter_simulator')
timescale_estimator = entry_point('timescale_estimator')
record = entry_point('record')
play = entry_point('play')
replay_offline = entry_point('replay_offline')
reindex = entry_point('reindex')
plot_bag = entry_point('plot_bag')
make_sample_bags = entry_point('make_sample_bags')
led_link_simulator = entry_point('led_link_simulator')
alignment = entry_point('alignment')
power_meter_driver = entry_point('power_meter_driver')
fit_noise = entry_point('fit_noise')
sweep = entry_point('sweep')
foxglove_bridge = entry_point('foxglove_bridge')
