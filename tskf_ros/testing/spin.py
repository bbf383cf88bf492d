"""spin_until: spin an executor until a condition holds, with a deadline."""

import time
from typing import Callable, Optional, Union

from rclpy.executors import Executor

# s: a bound on waiting for DDS (discovery, matching, delivery), never an assertion about
# timing; generous for a loaded machine, it costs nothing when things work
DEFAULT_TIMEOUT = 60.0


def spin_until(executor: Executor, condition: Callable[[], bool],
               timeout: float = DEFAULT_TIMEOUT,
               what: Optional[Union[str, Callable[[], str]]] = None) -> None:
    """
    Spin executor until condition() holds; raise TimeoutError after timeout seconds.

    The error says what never happened: `what` (a string, or a callable called only on
    failure to describe the state reached), else the condition's name.
    """
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            said = what() if callable(what) else what
            raise TimeoutError(f'timed out after {timeout:g} s waiting for '
                               f'{said or getattr(condition, "__name__", "the condition")}')
        executor.spin_once(timeout_sec=0.02)
