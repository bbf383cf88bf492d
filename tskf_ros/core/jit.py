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
How the compiled kernels run: numba on demand, and the same source interpreted until then.

`kernel` marks a function of the one implementation of an equation (kalman.py,
smoother.py).  Nothing imports numba until a kernel is first called, and numba compiles
only the signatures called (or loads them from its on-disk cache).  What a call does
before its kernel is compiled depends on the mode, `set_mode()` or $TSKF_JIT:

- 'wait' (the default): the first call compiles, or loads from the cache, and waits for
  it: numba's own behaviour (a tool that runs thousands of steps in one call).
- 'background' (the nodes): a call runs the kernel's Python source (numba's `py_func`,
  its nested kernels interpreted as well) while a thread compiles the signatures called so
  far; each kernel switches to its compiled form once that is ready.  A node publishes
  its first estimate without waiting for numba, with a cold cache, a read-only install,
  or none at all.  A kernel built ahead of time (tskf_ros.core.aot) runs that form from
  its first call: the process never imports numba for it.
- 'off': never compile, never import numba (the least memory: numba and LLVM take about
  100 MB of a process).

The cache: numba's own, next to the sources (`__pycache__`), or, where the install is
read-only, numba's per-user directory (`~/.cache/numba`, or $NUMBA_CACHE_DIR).
"""

import functools
import os
import sys
import threading
import types
from typing import Any, Callable, Optional

from tskf_ros.core import aot

MODES = ('wait', 'background', 'off')
MODE_VARIABLE = 'TSKF_JIT'
# numba.njit's options for every kernel: cache=True, error_model='numpy', nogil=True

_lock = threading.RLock()
_mode: Optional[str] = None
_kernels: dict[str, list['Kernel']] = {}        # module name -> its kernels, in order
_queue: list[tuple['Kernel', tuple]] = []       # (kernel, argument types' sample) to compile
_worker: Optional[threading.Thread] = None
# a kernel called from inside another kernel's interpreted source is compiled inside its
# caller (numba compiles the callees of a signature): queued on its own it would load a
# second, unused copy of its code (about 2 to 10 MB a kernel)
_inside = threading.local()


def mode() -> str:
    """Return the mode in force: the one set, else $TSKF_JIT's, else 'wait'."""
    if _mode is not None:
        return _mode
    chosen = os.environ.get(MODE_VARIABLE) or 'wait'
    return chosen if chosen in MODES else 'wait'


def set_mode(new: str) -> None:
    """Choose what a call does before its kernel is compiled (see MODES)."""
    global _mode
    if new not in MODES:
        raise ValueError(f'jit mode must be one of {", ".join(MODES)}, got {new!r}')
    _mode = new


class Kernel:
    """
    One kernel: its Python source (py_func) and, once compiled, numba's dispatcher.

    Calling it calls whichever runs now (see the module's modes).  `interpreted` is what
    runs in place of py_func when the source is interpreted (a helper whose loops pay off
    only compiled, such as a small matrix product, given as numpy's own operator).
    """

    def __init__(self, func: Callable, interpreted: Optional[Callable] = None) -> None:
        functools.update_wrapper(self, func)
        self.name: str = func.__name__
        self.py_func = func
        self.interpreted = interpreted or func
        self.dispatcher: Any = None
        self._call: Callable = self._first
        self._queued = False
        self._no_ahead = False
        _kernels.setdefault(func.__module__, []).append(self)

    def __call__(self, *args: Any) -> Any:
        """Run the kernel (compiled if it is ready, else as the mode says)."""
        return self._call(*args)

    def __repr__(self) -> str:
        """Say which kernel, and whether it runs compiled."""
        state = ('compiled' if self._call is self.dispatcher else
                 'interpreted' if self._call in (self._first, self.interpreted) else
                 'compiled ahead of time')
        return f'<kernel {self.py_func.__module__}.{self.name} ({state})>'

    @property
    def compiled(self) -> bool:
        """Tell whether calls run the compiled kernel."""
        return self.dispatcher is not None and self._call is self.dispatcher

    def _first(self, *args: Any) -> Any:
        now = mode()
        if now == 'wait':
            _compile_module(self.py_func.__module__)
            return self._call(*args)
        if now == 'background' and not getattr(_inside, 'depth', 0):
            ahead = None if self._no_ahead else aot.function(self.py_func.__module__,
                                                             self.name, self._not_ahead)
            if ahead is not None:
                self._call = ahead
                return self._call(*args)
            self._enqueue(args)
        return self._interpret(args)

    def _interpret(self, args: tuple) -> Any:
        """Run the source interpreted (its nested kernels are not queued on their own)."""
        nested = getattr(_inside, 'depth', 0)
        _inside.depth = nested + 1
        try:
            return self.interpreted(*args)
        finally:
            _inside.depth = nested

    def _not_ahead(self, args: tuple, error: Exception) -> Any:
        """Run a call the ahead-of-time form did not take (see tskf_ros.core.aot.function)."""
        if isinstance(error, ZeroDivisionError):
            # numba.pycc compiles with Python's error model, the dispatchers with numpy's
            # (a division by zero is inf or nan): this call interpreted
            return self._interpret(args)
        # not the argument types it was built for: numba's way from now on
        self._no_ahead = True
        self._call = self._first
        return self._first(*args)

    def _enqueue(self, args: tuple) -> None:
        global _worker
        with _lock:
            if self._queued:
                return
            self._queued = True
            _queue.append((self, args))
            if _worker is None or not _worker.is_alive():
                _worker = threading.Thread(target=_compile_queued, name='tskf_jit', daemon=True)
                _worker.start()


def kernel(func: Optional[Callable] = None, *,
           interpreted: Optional[Callable] = None) -> Any:
    """Mark a function as a kernel, bare or with `interpreted=` (see Kernel)."""
    if func is None:
        return lambda f: Kernel(f, interpreted)
    return Kernel(func, interpreted)


def _compile_module(module: str, switch: bool = True) -> None:
    """Make numba dispatchers for every kernel of a module; switch the calls to them."""
    with _lock:
        kernels = _kernels.get(module, [])
        if kernels and kernels[0].dispatcher is None:
            _dispatchers(kernels, module)
        if switch:
            for k in kernels:
                k._call = k.dispatcher


def _dispatchers(kernels: list[Kernel], module: str) -> None:
    """Make the numba dispatcher of each kernel of a module (nothing compiled yet)."""
    import numba      # noqa: I900 - imported here: loading numba costs about 1 s, 45 MB
    # each function is compiled with the module's globals, its kernels as dispatchers
    # (numba types a call of a dispatcher, not of a Kernel); the code objects are the
    # same, so numba's cache (keyed by file, name and line) is shared with py_func's
    space = dict(sys.modules[module].__dict__)
    # a kernel imported from another module (kalman's _mm in transitions) is typed as that
    # module's dispatcher
    for name, value in list(space.items()):
        if isinstance(value, Kernel) and value.py_func.__module__ != module:
            other = value.py_func.__module__
            if value.dispatcher is None:
                _dispatchers(_kernels[other], other)
            space[name] = value.dispatcher
    for k in kernels:
        f = k.py_func
        copy = types.FunctionType(f.__code__, space, f.__name__, f.__defaults__,
                                  f.__closure__)
        copy.__qualname__, copy.__doc__ = f.__qualname__, f.__doc__
        k.dispatcher = numba.njit(copy, cache=True, error_model='numpy', nogil=True)
        space[k.name] = k.dispatcher


def _compile_queued() -> None:
    """
    Compile the signatures called so far (the background mode's thread), then switch.

    The calls switch to the compiled kernels only once the queue is empty, all at once:
    the caller's thread then never compiles while this thread does (numba's compiler
    lock notwithstanding, LLVM aborted the process when both did).
    """
    done: list[Kernel] = []
    while True:
        with _lock:
            if not _queue:
                for k in done:
                    k._call = k.dispatcher
                return
            k, args = _queue.pop(0)
        try:
            _compile_in_background(k, args)
            done.append(k)
        except Exception as exc:  # noqa: B902 - the interpreted source keeps running
            print(f'tskf_ros: {k.name} stays interpreted: numba could not compile it '
                  f'({type(exc).__name__}: {exc})', file=sys.stderr)


def _compile_in_background(k: Kernel, args: tuple) -> None:
    """Compile (or load from the cache) k for the types of args."""
    import numba      # noqa: I900 - in this thread, not on the caller's path
    # dispatchers for the module, the kernels' calls left as they are for now
    _compile_module(k.py_func.__module__, switch=False)
    k.dispatcher.compile(tuple(numba.typeof(a) for a in args))


def ready(timeout: Optional[float] = None) -> bool:
    """Wait for the background compilation (up to timeout s); tell whether it is done."""
    worker = _worker
    if worker is not None:
        worker.join(timeout)
        return not worker.is_alive()
    return True
