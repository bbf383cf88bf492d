"""
The pytest plugin of tskf_ros (entry point pytest11): ROS isolation and in-process fixtures.

At start the run is kept on this machine and in a ROS domain of its own, unless the
environment already says otherwise (ROS_AUTOMATIC_DISCOVERY_RANGE, ROS_DOMAIN_ID) or the
ini option ``tskf_ros_isolate = false`` turns this off.
"""

import os
from typing import Any, Callable, Iterator, List

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    """Declare the ini option tskf_ros_isolate."""
    parser.addini('tskf_ros_isolate', type='bool', default=True,
                  help='tskf_ros: keep ROS 2 traffic on localhost and in a ROS_DOMAIN_ID of '
                  "this run's own where the environment does not set them (default true)")


def pytest_configure(config: pytest.Config) -> None:
    """Isolate the run's ROS 2 traffic before any test imports rclpy (see the module)."""
    if config.getini('tskf_ros_isolate'):
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        if not os.environ.get('ROS_DOMAIN_ID'):
            os.environ['ROS_DOMAIN_ID'] = str(os.getpid() % 100 + 1)


@pytest.fixture
def ros_context() -> Iterator[Any]:
    """Yield an initialized rclpy Context of the test's own; shut it down afterwards."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        context.try_shutdown()


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
