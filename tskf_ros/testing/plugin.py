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
The pytest plugin of tskf_ros (entry point pytest11): in-process ROS fixtures.

Loaded into every pytest session where tskf_ros is installed, it changes nothing there
until a test asks for one of its fixtures: no environment variable, no option, and no
rclpy import at load.  The ROS environment is set inside ``ros_environment`` (which
``ros_context`` uses), for that test only, and put back afterwards.
"""

import gc
import os
from typing import Any, Callable, Dict, Iterator, List

import pytest

# environment variable -> the value ros_environment gives it where the environment does not
# set it (the domain: one of this process's own, so that parallel runs do not meet)
ISOLATION = ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')


def isolated_values(environ: Dict[str, str]) -> Dict[str, str]:
    """Return the variables ros_environment sets: those of ISOLATION that environ lacks."""
    wanted = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
              'ROS_DOMAIN_ID': str(os.getpid() % 100 + 1)}
    return {name: value for name, value in wanted.items() if not environ.get(name)}


@pytest.fixture
def ros_environment() -> Iterator[Dict[str, str]]:
    """
    Keep the test's ROS 2 traffic on this machine and in a domain of its own.

    Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a ROS_DOMAIN_ID where the environment
    does not set them, for this test (and the processes it starts) only; yields the
    variables it set and restores the environment afterwards.
    """
    added = isolated_values(dict(os.environ))
    with pytest.MonkeyPatch.context() as patch:
        for name, value in added.items():
            patch.setenv(name, value)
        yield added


@pytest.fixture
def ros_context(ros_environment: Dict[str, str]) -> Iterator[Any]:
    """
    Yield an initialized rclpy Context of the test's own; shut it down and destroy it after.

    Its DDS participant lives until every node of the context is finalized, and a node
    in a reference cycle (every rclpy LifecycleNode is one: its state machine holds the node
    handle) is finalized only by the garbage collector.  A test process that keeps such
    participants gives its new ones ids beyond the 32 that localhost discovery tries per
    domain, and a node started in another process then never meets them.  So the fixture
    destroys the context and collects the garbage when the test ends.
    """
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        context.try_shutdown()
        context.destroy()
        gc.collect()


@pytest.fixture
def executor_kind() -> str:
    """Return the executor kind of ros_executor: 'single' (parametrize it for 'events')."""
    return 'single'


@pytest.fixture
def ros_executor(ros_context: Any, executor_kind: str) -> Iterator[Any]:
    """Yield an executor of executor_kind in ros_context; shut it down afterwards."""
    from tskf_ros.nodes.node_runner import make_executor

    executor = make_executor(executor_kind, context=ros_context)
    try:
        yield executor
    finally:
        executor.shutdown()


@pytest.fixture
def start_node(ros_context: Any, ros_executor: Any) -> Iterator[Callable[..., Any]]:
    """
    Yield start(node, *, parameters=None, params_file=None, **kwargs) -> the started node.

    node is an executable name of this package ('timescale_estimator', ...) or any Node
    class; the node is created in ros_context with the parameter overrides and added to
    ros_executor (see tskf_ros.testing.start_in_process).  Every node started is destroyed
    after the test.
    """
    from tskf_ros.testing.nodes import start_in_process

    started: List[Any] = []

    def start(node: Any, **kwargs: Any) -> Any:
        made = start_in_process(node, ros_context, ros_executor, **kwargs)
        started.append(made)
        return made

    yield start
    for node in reversed(started):
        ros_executor.remove_node(node)
        node.destroy_node()
