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

"""How a node runs: its executor, `--help` without ROS, the Jazzy main loop, one-line errors."""

import array
import os
import re
import signal
import sys
import threading
from types import SimpleNamespace
from typing import Callable, NoReturn, Optional, Sequence, TYPE_CHECKING, Union

import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from tskf_ros.core import jit
from tskf_ros.messages.context import end_context
from tskf_ros.messages.parameter_schema import (ParameterError, ParameterSchema,
                                                SchemaFormatError)
from tskf_ros.messages.parameter_validation import format_number
from tskf_ros.messages.parameters import (file_values, given_parameters, parameters_for_node,
                                          read_params_yaml)

import yaml

if TYPE_CHECKING:
    import argparse

    from rclpy.experimental import EventsExecutor


def _events_executor(context=None) -> 'EventsExecutor':
    """Return an rclpy.experimental.EventsExecutor (its module imported only for it)."""
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


# The executors a node can run on (`--executor`, or TSKF_EXECUTOR in the environment).
# 'single' is rclpy's SingleThreadedExecutor, Jazzy's stable executor, which rebuilds its
# wait set on every spin; 'events' is rclpy.experimental.EventsExecutor, which dispatches
# from callbacks of the middleware (doc/benchmarks.md has both, measured).
EXECUTORS: dict[str, Callable[..., Union[Executor, 'EventsExecutor']]] = {
    'single': SingleThreadedExecutor, 'events': _events_executor}
DEFAULT_EXECUTOR = 'single'
EXECUTOR_VARIABLE = 'TSKF_EXECUTOR'
# s: the longest EventsExecutor.spin_once between two checks of the context.  rclpy 7.1's
# EventsExecutor.spin() (and its spin_once without a timeout) never returns after SIGINT
# or SIGTERM, spinning a core; its spin_once with a timeout returns at once, raising
# KeyboardInterrupt or ExternalShutdownException (test/nodes/test_node_base.py checks
# both executors).  SingleThreadedExecutor.spin() needs no such loop.
SPIN_TIMEOUT = 1.0
# a parameter override refused at declaration (out of its range, wrong type), or a schema
# that cannot be read (a broken installation): one line
ROS_PARAMETER_ERRORS = (InvalidParameterTypeException, InvalidParameterValueException,
                        ParameterError, SchemaFormatError)
# exit status of a command line the node cannot parse (as argparse's usage errors)
EXIT_USAGE = 2
# s the clean-up after the spin (executor, node, context) may take before the process
# ends anyway: a node ends within a bound of SIGINT or SIGTERM whatever rcl does meanwhile
CLEANUP_BOUND = 3.0
# s a SIGINT's KeyboardInterrupt has to reach run_node's clean-up before the context is
# shut down under the spin instead (_shut_down_on_sigint); set once the clean-up begins
SIGINT_GRACE = 1.0
_CLEANING = threading.Event()
# rcl's source locations in its error strings (", at /project/src/parse.c:935")
RCL_LOCATION = re.compile(r',? at \S+:\d+')


def executor_kind(kind: Optional[str] = None) -> str:
    """Return the executor kind asked for: kind, else $TSKF_EXECUTOR, else the default."""
    kind = kind or os.environ.get(EXECUTOR_VARIABLE) or DEFAULT_EXECUTOR
    if kind not in EXECUTORS:
        raise ValueError(f'executor must be one of {", ".join(EXECUTORS)}, got {kind!r}')
    return kind


def make_executor(kind: Optional[str] = None, *,
                  context=None) -> Union[Executor, 'EventsExecutor']:
    """Return a new executor of the kind (see executor_kind) in context."""
    return EXECUTORS[executor_kind(kind)](context=context)


def spin(executor: Executor, context=None) -> None:
    """
    Spin executor until its context shuts down (SIGINT, SIGTERM, rclpy.shutdown).

    An rclpy Executor (SingleThreadedExecutor, the default) spins with its own spin(),
    which returns on any of them; the EventsExecutor, which is no rclpy Executor, in a
    loop of spin_once calls with a timeout (SPIN_TIMEOUT).
    """
    if isinstance(executor, Executor):
        executor.spin()
        return
    context = context or rclpy.get_default_context()
    while context.ok():
        executor.spin_once(timeout_sec=SPIN_TIMEOUT)


def ros_arguments_error(exc: RuntimeError) -> str:
    """Return rcl's refusal of the ROS arguments as one line, without its source locations."""
    text = RCL_LOCATION.sub('', str(exc)).strip().removeprefix('Failed to parse ROS arguments: ')
    if text.startswith('['):
        return f'unknown ROS argument(s) {text}'
    text = f'bad ROS argument: {text}'
    if 'parameter override rule' in text:
        text += (' (the value after := is YAML: quote a string YAML cannot read, e.g. '
                 """-p 'backend:="@py"')""")
    return text


def parse_args(prog: str, description: str,
               argv: Optional[list] = None) -> Union['argparse.Namespace', SimpleNamespace]:
    """
    Parse the non-ROS arguments (`--help` prints usage and exits without starting ROS).

    ROS arguments rcl cannot parse (a malformed `-p`, `-r` or `--params-file`, an unknown
    `--ros-args` flag) end the process with one line and exit status EXIT_USAGE.  Without
    any non-ROS argument (a node's usual start) argparse is not even imported.
    """
    try:
        # rcl's RCLInvalidROSArgsError and UnknownROSArgsError are RuntimeErrors
        args = remove_ros_args(sys.argv if argv is None else argv)[1:]
    except RuntimeError as exc:
        print(f'{prog}: cannot start: {ros_arguments_error(exc)}', file=sys.stderr)
        sys.exit(EXIT_USAGE)
    if not args:
        return SimpleNamespace(executor=None)
    import argparse
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument('--executor', choices=sorted(EXECUTORS), default=None,
                        help=f'the rclpy executor to spin on (default: ${EXECUTOR_VARIABLE} '
                        f'if set, else {DEFAULT_EXECUTOR}): single = SingleThreadedExecutor, '
                        'events = rclpy.experimental.EventsExecutor')
    return parser.parse_known_args(args)[0]


def unused_parameter_file(node: Node, argv: Sequence[str]) -> str:
    """Return a warning if a --params-file was given but set none of this node's parameters."""
    files = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == '--params-file']
    own = set()
    for path in files:
        try:
            own |= parameters_for_node(path, node.get_fully_qualified_name())
        except (OSError, yaml.YAMLError):
            continue        # rcl refused such a file before the node started
    if files and not own - {'use_sim_time'}:
        return (f'the parameter file(s) {", ".join(files)} set none of the parameters of '
                f'{node.get_fully_qualified_name()}: it runs on its built-in defaults. Key '
                f'the section /**/{node.get_name()} (or /**) so that it applies in any '
                'namespace')
    return ''


def run_node(factory: Callable[[], Node], *, name: str, description: str,
             startup_errors: tuple = (), args: Optional[list] = None) -> None:
    """
    Run one node until Ctrl-C or shutdown, in the Jazzy form of ros2/demos.

    An exception of `startup_errors` (bad parameters) ends the process with its message
    on stderr and exit code 1, not a traceback.  `--executor single|events` chooses the
    executor (see EXECUTORS).

    SIGINT or SIGTERM ends the process within about CLEANUP_BOUND seconds of the spin's
    end, in any state: an rcl error that a callback meets because the signal handler
    shut the context down under it is the shutdown, not a failure (no traceback); after
    the clean-up the process exits at once (os._exit, stdout and stderr flushed), without
    the interpreter's teardown, which takes seconds of a loaded machine's CPU (the
    collection of numpy's, scipy's and numba's module objects); and a clean-up that takes
    longer than CLEANUP_BOUND is cut short the same way, with one line saying so.
    """
    options = parse_args(name, description, args)
    try:
        kind = executor_kind(options.executor)
    except ValueError as exc:
        print(f'{name}: cannot start: {exc}', file=sys.stderr)
        sys.exit(1)
    try:
        # the kernels run interpreted until numba has them compiled: the node starts at
        # once, whatever the state of numba's cache (unless $TSKF_JIT says otherwise)
        jit.set_mode(os.environ.get(jit.MODE_VARIABLE) or 'background')
    except ValueError as exc:
        print(f'{name}: cannot start: {jit.MODE_VARIABLE}: {exc}', file=sys.stderr)
        sys.exit(1)
    rclpy.init(args=args)
    if args is None:
        _shut_down_on_sigint()
    node = executor = None
    status = 0
    try:
        node = factory()
        if args is None and hasattr(node, 'own_process'):
            node.own_process()      # the process is the node's: see ReconfigurableNode
        warning = limit_blas_threads()
        if warning:
            node.get_logger().warning(warning)
        warning = unused_parameter_file(node, sys.argv if args is None else args)
        if warning:
            node.get_logger().error(warning)
        for warning in unknown_parameters(node, sys.argv if args is None else args):
            node.get_logger().warning(warning)
        why = dropped_parameters(node, sys.argv if args is None else args)
        if why:
            raise ParameterError(why)
        executor = make_executor(kind)
        executor.add_node(node)
        if _interrupted_before():
            raise KeyboardInterrupt
        spin(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        _quiet_unraisable()
    except startup_errors + ROS_PARAMETER_ERRORS as exc:
        print(f'{name}: cannot start: {exc}', file=sys.stderr)
        status = 1
    except Exception:  # noqa: B902 - re-raised unless the signal handler caused it
        if rclpy.ok():
            raise           # a failure of the node itself: its traceback
        _quiet_unraisable()
    finally:
        _CLEANING.set()
        # the bound and the immediate exit are the process's (argv its own); a caller that
        # passes args (a test, in-process) gets SystemExit and keeps its interpreter
        watchdog = threading.Timer(CLEANUP_BOUND, _cleanup_overran, args=(name, status))
        watchdog.daemon = True
        if args is None:
            watchdog.start()
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        end_context()
        watchdog.cancel()       # (a failure goes on to its traceback and the usual exit)
    if args is not None:
        sys.exit(status)
    _exit(status)


def _shut_down_on_sigint() -> None:
    """
    Make a SIGINT also shut the default context down, as rclpy's own SIGTERM handler does.

    rclpy's SIGINT handler only wakes the executors and leaves the ending to the Python
    handler's KeyboardInterrupt (the console scripts' runner's SigintFlag).  An interrupt
    raised where Python can only report it (a weakref callback while a module loads in a
    callback) is lost, or delivered again by the runner with `_thread.interrupt_main`,
    which no rcl_wait wakes for: a node whose wait set has nothing else to wake it (the
    driver waiting to be configured) then spins on.  The flag's `first` runs in the handler
    before the interrupt and starts a thread that shuts the context down unless the
    clean-up has begun within SIGINT_GRACE seconds (the usual end: the interrupt reached
    the spin); the executor's spin then returns however the interrupt fared.  A thread,
    not the handler itself: the handler may run while this thread holds the context's
    lock (in `ok()`).  Only for the process's own runner.
    """
    owner = getattr(signal.getsignal(signal.SIGINT), '__self__', None)
    if owner is not None and callable(getattr(owner, 'is_set', None)) \
            and getattr(owner, 'first', False) is None:
        owner.first = lambda: threading.Thread(target=_end_unless_cleaning,
                                               daemon=True).start()


def _end_unless_cleaning() -> None:
    """Shut the default context down unless run_node's clean-up begins within the grace."""
    if not _CLEANING.wait(SIGINT_GRACE):
        end_context()


def _interrupted_before() -> bool:
    """
    Tell whether a SIGINT came while the node's modules imported (and may have been lost).

    The console scripts' runner takes SIGINT as KeyboardInterrupt and remembers it (its
    handler's `is_set()`); an interrupt raised inside importlib's module-lock callback is
    printed as "Exception ignored" and lost, and the node would start and run on.  rclpy
    handles later signals itself (and passes them on to that handler).
    """
    owner = getattr(signal.getsignal(signal.SIGINT), '__self__', None)
    is_set = getattr(owner, 'is_set', None)
    return bool(is_set()) if callable(is_set) else False


def _quiet_unraisable() -> None:
    """
    Say nothing of errors in destructors from here on: the process is ending on a signal.

    A signal during the construction of an rclpy object leaves it half built, and its
    __del__ then fails ("Exception ignored in: <function Executor.__del__ ...>
    AttributeError: ... '_sigint_gc'", seen for 2 of 100 signals to the driver).
    """
    sys.unraisablehook = _ignore


def _ignore(unraisable: object) -> None:
    return None


def _cleanup_overran(name: str, status: int) -> None:
    print(f'{name}: the shutdown took longer than {CLEANUP_BOUND:g} s; exiting without '
          'waiting for it', file=sys.stderr)
    _exit(status)


def _exit(status: int) -> NoReturn:
    """End the process now (stdout and stderr flushed), without the interpreter's teardown."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):   # a closed or broken pipe: nothing more to say
            pass
    os._exit(status)


def unknown_parameters(node: Node, argv: Sequence[str]) -> list:
    """
    Return one warning for each parameter the command line gives that node does not declare.

    rclpy ignores such a value without a word (a misspelt `perod`); the warning names
    where it was given and the closest declared name (difflib), if one is close.
    """
    declared = node.list_parameters([], 0).names
    warnings = []
    for name, where in given_parameters(argv, node.get_name(),
                                        node.get_fully_qualified_name()).items():
        if name in declared:
            continue
        import difflib      # only for a name the node does not have
        close = difflib.get_close_matches(name, declared, n=1)
        warnings.append(f'parameter {name!r} ({where}) is not a parameter of '
                        f'{node.get_fully_qualified_name()} and is ignored'
                        + (f': did you mean {close[0]!r}?' if close else ''))
    return warnings


def dropped_parameters(node: Node, argv: Sequence[str]) -> str:
    """
    Return why node cannot start on a parameter value the command line gives but rcl dropped.

    rcl reads the values of `-p NAME:=VALUE` and of a parameter file as YAML, and drops an
    empty list (`-p Q:=[]`, `Q: []`) without a word: it has no parameter type.  The node
    would run on the value it has without it (its default, or a file's), unless that is
    an empty list too.  A parameter of the node's schema whose value on the command line
    (where rcl takes it from: given_parameters) is an empty list is refused; '' if none.
    """
    schema = getattr(node, 'schema', None)
    if not isinstance(schema, ParameterSchema):
        return ''
    fqn = node.get_fully_qualified_name()
    for name, where in given_parameters(argv, node.get_name(), fqn).items():
        if name not in schema.names or not _empty_list(where, name, fqn):
            continue
        value = node.get_parameter(name).value
        if isinstance(value, (list, array.array)):
            if not len(value):
                continue                # an empty list asked, an empty list it is
            shown = '[' + ', '.join(map(format_number, value)) + ']'
        else:
            shown = format_number(value)
        return (f'{name} ({where}) did not reach the node: rcl drops an empty list (it has '
                f'no parameter type), so it would run with {name} = {shown}; give {name} '
                'its entries, or leave it out')
    return ''


def _empty_list(where: str, name: str, node_fqn: str) -> bool:
    """Tell whether given_parameters' `-p NAME:=VALUE` or file gives name an empty list."""
    try:
        if where.startswith('-'):
            return read_params_yaml(where.partition(':=')[2]) == []
        return file_values(where, node_fqn).get(name) == []
    except (OSError, yaml.YAMLError):
        return False                    # rcl refused such an argument before the node


def limit_blas_threads() -> str:
    """
    Run BLAS/OpenMP on one thread: a node filters one sample at a time (small matrices).

    threadpoolctl is optional (the extra `threads`): without it, and with no
    OPENBLAS_NUM_THREADS / OMP_NUM_THREADS in the environment, return a warning.
    """
    # without a limit OpenBLAS runs small products on every core: about 10 ms per sample
    # of a jittered 1 kHz stream against 0.5 ms on one, under `ros2 run` (where nothing
    # sets OPENBLAS_NUM_THREADS); called once the node is built, so that the libraries it
    # loaded are covered
    try:
        from threadpoolctl import threadpool_limits
    except ModuleNotFoundError:
        if any(os.environ.get(v) for v in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS')):
            return ''
        return ('threadpoolctl is not installed, so BLAS may use every core for small '
                "products (slower): pip install 'tskf_ros[threads]', or set "
                'OPENBLAS_NUM_THREADS=1 before starting the node')
    threadpool_limits(limits=1)
    return ''
