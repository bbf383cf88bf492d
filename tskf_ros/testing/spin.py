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
