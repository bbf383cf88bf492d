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
Test your own code against tskf_ros's nodes in-process: a pytest plugin and its helpers.

Installed with the package and loaded by pytest through the ``pytest11`` entry point, so a
test file needs no conftest; loaded, it changes nothing until a test uses a fixture.  The
fixtures: ``ros_environment`` (localhost and a ROS domain of the test's own, restored
after), ``ros_context`` (a fresh rclpy Context of the test's own), ``executor_kind``
('single' by default; parametrize it to run on both), ``ros_executor`` (an executor of
that kind in that context) and ``start_node`` (a node of this package, or any Node class,
started in that context with parameter overrides and added to the executor).
``spin_until`` waits on a condition with a deadline.

The helpers are imported on first use (they import rclpy), so that pytest loading the
plugin (this package's ``plugin`` module) imports no rclpy.
"""

from tskf_ros.core.lazy_names import lazy_names

__all__ = ['NODES', 'node_class', 'spin_until', 'start_in_process']

# public name -> the module of this package that defines it
_HOMES = {'NODES': 'nodes', 'node_class': 'nodes', 'start_in_process': 'nodes',
          'spin_until': 'spin'}

__getattr__, __dir__ = lazy_names(__name__, _HOMES, globals())
