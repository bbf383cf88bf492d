"""
Test your own code against tskf_ros's nodes in-process: a pytest plugin and its helpers.

Installed with the package and loaded by pytest through the ``pytest11`` entry point, so a
test file needs no conftest.  The fixtures: ``ros_context`` (a fresh rclpy Context of the
test's own), ``executor_kind`` ('single' by default; parametrize it to run on both),
``ros_executor`` (an executor of that kind in that context) and ``start_node`` (a node of
this package, or any Node class, started in that context with parameter overrides and
added to the executor).  ``spin_until`` waits on a condition with a deadline.
"""

from tskf_ros.testing.nodes import node_class, NODES, start_in_process
from tskf_ros.testing.spin import spin_until

__all__ = ['NODES', 'node_class', 'spin_until', 'start_in_process']
