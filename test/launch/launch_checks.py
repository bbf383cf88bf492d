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
What the launch_testing tests of launch/ share: the skip, the launch, a listener, exit codes.

A launch file is started where launch_ros and launch_testing import and tskf_ros is in the
ament index (a sourced workspace: colcon test); elsewhere (the venv of ./run, where launch
and launch_ros have no wheels) the tests skip, saying which of them is missing.
"""

import importlib.util
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import pytest

REPO = Path(__file__).resolve().parents[2]
NAMESPACE = 'launch_test'
# s: a bound on waiting for the launched nodes (start, discovery, first messages), never an
# assertion about timing
DEADLINE = 300.0


def why_not_runnable() -> Optional[str]:
    """Return why the launch files cannot be started here, or None if they can."""
    for module in ('launch', 'launch_ros', 'launch_testing'):
        if importlib.util.find_spec(module) is None:
            return (f'{module} is not installed (no wheel: it comes with ROS 2 Jazzy); '
                    'test/package/test_launch_files.py checks the launch files statically')
    from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

    try:
        get_package_share_directory('tskf_ros')
    except PackageNotFoundError:
        return 'tskf_ros is not in the ament index: build and source a workspace (colcon)'
    return None


def skip_unless_runnable() -> None:
    """Skip the calling test module, with the reason, where a launch file cannot run."""
    reason = why_not_runnable()
    if reason:
        pytest.skip(reason, allow_module_level=True)


def launch_file(name: str) -> str:
    """Return the path of a launch file of this repository's launch/ folder."""
    return str(REPO / 'launch' / name)


def receive(topics: Dict[str, Any], count: int = 3,
            more: Optional[Callable[[Dict[str, List]], bool]] = None) -> Dict[str, List]:
    """
    Subscribe to topics ({topic: message class}) and return the messages got on each.

    Waits until every topic has count messages (and more(got), if given, holds), at most
    DEADLINE seconds; raises TimeoutError naming the topics still short.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tskf_ros.testing import spin_until

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('launch_test_listener', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    got: Dict[str, List] = {topic: [] for topic in topics}
    # best effort matches a reliable publisher and a best-effort one alike
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
    for topic, msg_type in topics.items():
        node.create_subscription(msg_type, topic, got[topic].append, qos)
    try:
        spin_until(executor, lambda: all(len(m) >= count for m in got.values())
                   and (more is None or more(got)), DEADLINE,
                   lambda: 'messages on ' + ', '.join(
                       f'{t} ({len(m)} of {count})' for t, m in got.items()))
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    return got


def assert_each_receives(case: Any, topics: Dict[str, Any], count: int = 3) -> None:
    """Assert (in a unittest case) that each of topics carries count messages (see receive)."""
    got = receive(topics, count)
    for topic, messages in got.items():
        case.assertGreaterEqual(len(messages), count, topic)


def launch_description(name: str) -> Any:
    """
    Return a launch test's description: launch/<name> in NAMESPACE, as `ros2 launch` would.

    Its generate_test_description returns this (launch_testing calls it there).
    """
    import launch
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    import launch_testing.actions

    return launch.LaunchDescription([
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(launch_file(name)),
            launch_arguments={'namespace': NAMESPACE, 'log_level': 'warn'}.items()),
        launch_testing.actions.ReadyToTest(),
    ])


class ExitCodes:
    """
    The post-shutdown check that every launched process exited with status 0.

    A mixin, no test case of its own: a test module's TestShutdown(ExitCodes, TestCase),
    marked with launch_testing.post_shutdown_test(), runs it once the launch has ended.
    """

    def test_every_node_exits_with_status_0(self, proc_info: Any) -> None:
        """Assert every process's exit code is 0 (launch_testing passes proc_info)."""
        import launch_testing.asserts

        launch_testing.asserts.assertExitCodes(proc_info)
