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

"""Fixtures of the node tests (the ROS environment and ros_context: test/conftest.py)."""

import pytest
import rclpy

from tskf_ros.nodes.node_runner import make_executor


@pytest.fixture
def loop(ros_context, executor_kind):
    """Yield an executor (each kind) with a client node; the nodes listed are destroyed after."""
    executor = make_executor(executor_kind, context=ros_context)
    client = rclpy.create_node('citizen_client', context=ros_context)
    executor.add_node(client)
    nodes = [client]
    yield executor, client, nodes
    for n in nodes:             # off the executor first, then shut down, then destroyed
        if n in executor.get_nodes():
            executor.remove_node(n)
    executor.shutdown()
    for n in nodes:
        n.destroy_node()
