"""What every node's executable shares: `--help` without ROS, and the Jazzy main loop."""

import argparse
import sys
from typing import Callable, Optional

from rcl_interfaces.msg import FloatingPointRange
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.utilities import remove_ros_args


def float_range(lo: float, hi: float) -> dict:
    """Return ParameterDescriptor keyword arguments for a closed floating-point range."""
    return {'floating_point_range': [FloatingPointRange(from_value=lo, to_value=hi)]}


def parse_args(prog: str, description: str,
               argv: Optional[list] = None) -> argparse.Namespace:
    """Parse the non-ROS arguments (`--help` prints usage and exits without starting ROS)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    args = remove_ros_args(sys.argv if argv is None else argv)[1:]
    return parser.parse_known_args(args)[0]


def run_node(factory: Callable[[], Node], *, name: str, description: str,
             startup_errors: tuple = (), args: Optional[list] = None) -> None:
    """
    Run one node until Ctrl-C or shutdown, in the Jazzy form of ros2/demos.

    An exception of `startup_errors` (bad parameters) ends the process with its message
    on stderr and exit code 1, not a traceback.
    """
    parse_args(name, description, args)
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except startup_errors as exc:
        print(f'{name}: cannot start: {exc}', file=sys.stderr)
        sys.exit(1)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
