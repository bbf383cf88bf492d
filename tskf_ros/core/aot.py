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
The nodes' kernels compiled ahead of time: the same sources, no numba in the process.

numba's ahead-of-time compiler (`numba.pycc`) builds the kernels that the nodes call from
Python, for the float64 arrays they call them with, into one extension module.  A node
(tskf_ros.core.jit's 'background' mode) calls that module's functions: it does not import
numba or LLVM, which take about 130 MiB of a process to load a kernel from numba's cache
(the extension module about 1 MiB).  The kernels these functions call are compiled into
them from the same Python sources as numba's just-in-time dispatchers.

    python -m tskf_ros.core.aot [--output DIR]

builds the module (about 1 to 3 minutes; a C compiler and Python's headers are needed) into
DIR, else the first writable of the package's `core/__pycache__` and the per-user cache
(`$XDG_CACHE_HOME`, or `~/.cache`, `/tskf_ros`).  Its file name carries a digest of the
kernels' sources: a module built from other sources is never loaded.  Without the module a
node compiles its kernels in the background as before; so does a process with $TSKF_AOT=off.
With --if-possible (what setup.py's build runs, so `colcon build` installs the module
inside the package) a missing numba or compiler, or a failed build, is one line and exit
status 0: the package builds without it.
"""

import hashlib
import os
from pathlib import Path
import shutil
import sys
import sysconfig
import types
from typing import Any, Callable, Optional
import warnings

import numpy as np

CORE = Path(__file__).resolve().parent
SOURCES = ('kalman.py', 'transitions.py', 'jit.py', 'aot.py')  # what the module is built from
SWITCH = 'TSKF_AOT'           # 'off': never load the module (numba's dispatchers only)
ENVIRONMENT = 'TSKF_AOT_DIR'    # a directory searched first (and built into, if writable)
# what a node does without the module (the line a package build prints when it builds none)
WITHOUT = ('the nodes will compile their kernels with numba in the background at start '
           '(a slower start, about 130 MiB more memory), or interpret them without numba')
# argument codes: a C-contiguous float64 vector 'v', matrix 'm', stack 's'; float64 'f';
# boolean 'b'
EXPORTS: tuple[tuple[str, str, str], ...] = (
    # the estimator: a step over a new mu (jittered stamps), over a cached mu, the
    # innovation test, the Euler jump
    ('transitions', 'jump_update_predict', 'vmvmmvmmmssffb'),
    ('kalman', 'update_predict', 'vmvmmvmmv'),
    ('kalman', 'mahalanobis2', 'vmvmmv'),
    # the same two writing their arrays into the caller's (what the filter's step and the
    # gate call: a returned array costs numba.pycc an unpickling per call)
    ('kalman', 'update_predict_into', 'vmvmmvmmvvmvmvm'),
    ('kalman', 'mahalanobis2_into', 'vmvmmvv'),
    ('transitions', 'euler', 'mmmf'),
    # the alignment node: the EKF's update over a stack of one
    ('kalman', 'update_batch', 'msmssm'),
    # the alignment node with axes 2: the conical-scan EKF's predict and (iterated) update
    ('kalman', 'predict_batch', 'msmmm'),
    ('kalman', 'update_runs', 'msmssm'),
)

_FLOAT64 = np.dtype(np.float64)
_loaded: Optional[types.ModuleType] = None
_looked = False


def digest() -> str:
    """Return a digest of the kernels' sources (and of this list of exports)."""
    h = hashlib.sha256()
    for name in SOURCES:
        h.update((CORE / name).read_bytes())
    return h.hexdigest()[:16]


def module_name() -> str:
    """Return the extension module's name for the sources as they are."""
    return f'tskf_kernels_{digest()}'


def filename() -> str:
    """Return the extension module's file name: its name, then this interpreter's suffix."""
    return module_name() + sysconfig.get_config_var('EXT_SUFFIX')


def directories() -> list[Path]:
    """Return where the module is looked for, in order (and built into: the first writable)."""
    found = [Path(os.environ[ENVIRONMENT])] if os.environ.get(ENVIRONMENT) else []
    cache = Path(os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache')
    return found + [CORE / '__pycache__', cache / 'tskf_ros']


def export_name(module: str, kernel: str) -> str:
    """Return the name of a kernel's function in the extension module."""
    return f'{module.rpartition(".")[2]}__{kernel}'


def load() -> Optional[types.ModuleType]:
    """Return the extension module built from these sources, or None if there is none."""
    global _loaded, _looked
    if _looked:
        return _loaded
    _looked = True
    if os.environ.get(SWITCH) == 'off':
        return None
    try:
        name, file = module_name(), filename()
    except OSError:         # a source file not readable: no module can be trusted
        return None
    for directory in directories():
        path = directory / file
        if path.is_file():
            import importlib.util      # noqa: I900 - only where a module is there to load
            spec = importlib.util.spec_from_file_location(name, path)
            if spec is None or spec.loader is None:
                continue
            try:
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
            except ImportError:     # built for another interpreter or a damaged file
                continue
            _loaded = module
            return module
    return None


def function(module: str, kernel: str,
             otherwise: Callable[[tuple, Exception], Any]) -> Optional[Callable[..., Any]]:
    """
    Return a call of the ahead-of-time compiled form of a kernel, or None if there is none.

    The call runs the compiled form for arguments of the types it was built for, and
    `otherwise(args, error)` for any other: a TypeError for other types (numba.pycc's own
    functions do not check an array's dtype, dimensions or layout: they would read it as
    the type built), or the ZeroDivisionError or TypeError the compiled form raised.  The
    types are checked at each call (an array's dtype, shape and flags can change in
    place), the check inlined in the one call: a loop over the array arguments, the dtype
    compared by identity first (float64 arrays share numpy's one descriptor).
    """
    built = load()
    compiled = None if built is None else getattr(built, export_name(module, kernel), None)
    codes = next((c for m, k, c in EXPORTS if f'tskf_ros.core.{m}' == module and k == kernel),
                 None)
    if compiled is None or codes is None:
        return None
    count = len(codes)
    last = max((i for i, c in enumerate(codes) if c in 'vms'), default=-1)
    # each argument's dimensions up to the last array (0: a scalar, converted by the call)
    ndims = tuple('_vms'.find(c) if c in 'vms' else 0 for c in codes[:last + 1])
    ndarray, float64 = np.ndarray, _FLOAT64

    def call(*args: Any) -> Any:
        if len(args) == count:
            for a, ndim in zip(args, ndims):
                if ndim and not (a.__class__ is ndarray
                                 and ((d := a.dtype) is float64 or d == float64)
                                 and a.ndim == ndim
                                 and (f := a.flags).c_contiguous and f.writeable):
                    break
            else:
                try:
                    return compiled(*args)
                except (TypeError, ZeroDivisionError) as exc:
                    return otherwise(args, exc)
        return otherwise(args, TypeError(
            f'{kernel} takes {count} arguments, float64 arrays C-contiguous and writeable '
            f'of {codes} dimensions (v 1, m 2, s 3)'))
    call.__name__ = kernel
    return call


def _types(codes: str) -> tuple:
    from numba import types      # noqa: I900 - only to build
    of = {'v': types.float64[::1], 'm': types.float64[:, ::1],
          's': types.float64[:, :, ::1], 'f': types.float64, 'b': types.boolean}
    return tuple(of[c] for c in codes)


def build(output: Optional[Path] = None) -> Path:
    """Build the extension module into output (else the first writable directory)."""
    from numba.pycc import CC      # noqa: I900 - only to build
    import importlib              # noqa: I900
    from tskf_ros.core import jit
    targets = [output] if output else directories()
    for target in targets:
        try:
            target.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(target, os.W_OK):
            break
    else:
        raise OSError('no writable directory among ' + ', '.join(map(str, targets)))
    name = module_name()
    cc = CC(name)
    for module, kernel, codes in EXPORTS:
        full = f'tskf_ros.core.{module}'
        k = getattr(importlib.import_module(full), kernel)
        jit._compile_module(full, switch=False)
        arguments = _types(codes)
        k.dispatcher.compile(arguments)     # its return type, as numba infers it
        signature = next(s for s in k.dispatcher.nopython_signatures if s.args == arguments)
        cc.export(export_name(full, kernel), signature)(k.dispatcher.py_func)
    built = target / filename()
    # compiled beside it, then renamed: a build cut short leaves no module under its name
    import tempfile               # noqa: I900 - only to build
    with tempfile.TemporaryDirectory(prefix='.building-', dir=target) as staging:
        cc.output_dir = staging
        cc.compile()
        os.replace(Path(staging) / built.name, built)
    for old in target.glob('tskf_kernels_*'):      # modules of earlier sources
        if old != built:
            old.unlink(missing_ok=True)
    return built


def build_if_possible(output: Optional[Path] = None) -> tuple[Optional[Path], str]:
    """
    Build the module unless numba or a C compiler is missing; never raise.

    Return the module's path (None when none was built) and one line saying what happened:
    a package build (setup.py) goes on without the module, whose nodes then compile their
    kernels in the background.  $TSKF_AOT=off skips the build.
    """
    if os.environ.get(SWITCH) == 'off':
        return None, f'{SWITCH}=off: not compiled ahead of time: {WITHOUT}'
    try:
        from numba.core.errors import NumbaPendingDeprecationWarning  # noqa: I900 - to build
    except ImportError as exc:
        return None, (f'numba is not installed ({exc}): {WITHOUT}; to build them with the '
                      'package: install numba (rosdep key python3-numba-pip), build again')
    done = "the nodes' kernels compiled ahead of time: "
    if output is not None and (output / filename()).is_file():     # a build again
        return output / filename(), done + str(output / filename())
    compiler = (os.environ.get('CC') or sysconfig.get_config_var('CC') or 'cc').split()[0]
    if shutil.which(compiler) is None:
        return None, (f'no C compiler ({compiler}): {WITHOUT}; to build them with the '
                      'package: apt install gcc python3-dev, build again')
    try:
        with warnings.catch_warnings():     # numba.pycc's pending deprecation (doc/)
            warnings.simplefilter('ignore', NumbaPendingDeprecationWarning)
            path = build(output)
    except Exception as exc:  # noqa: B902 - a failed compile must not fail the package
        reason = (str(exc).strip().splitlines() or [''])[-1][:200]
        return None, (f'the ahead-of-time build failed ({type(exc).__name__}: {reason}): '
                      f'{WITHOUT}')
    return path, done + str(path)


def main(args: Optional[list] = None) -> None:
    """Build the module (the command line)."""
    import argparse               # noqa: I900 - the command line's alone
    parser = argparse.ArgumentParser(
        prog='python -m tskf_ros.core.aot',
        description="Compile the nodes' kernels ahead of time (numba.pycc) into an "
                    'extension module, so that the nodes run them without numba.')
    parser.add_argument('--output', type=Path, default=None,
                        help='directory to write the module into (default: the first '
                             'writable of ' + ', '.join(map(str, directories())) + ')')
    parser.add_argument('--if-possible', action='store_true',
                        help='without numba or a C compiler, or when the build fails, say so '
                             'in one line and exit 0 (a package build goes on without it)')
    options = parser.parse_args(args)
    if options.if_possible:
        print(build_if_possible(options.output)[1])
        return
    try:
        path = build(options.output)
    except OSError as exc:
        print(f'tskf_ros.core.aot: cannot build: {exc}', file=sys.stderr)
        sys.exit(1)
    print(path)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
