"""Ending an rclpy context when a signal handler may end it at the same moment."""

from typing import Optional

import rclpy
from rclpy.context import Context


def end_context(context: Optional[Context] = None) -> None:
    """
    Shut a context down (the default one if None), quietly if it is already shut down.

    `rclpy.try_shutdown` checks `ok()` and then shuts down; rclpy's SIGINT/SIGTERM handler
    may shut the context down between the two, and rcl then raises "rcl_shutdown already
    called" (RCLError, a RuntimeError).  That is the end we asked for, not a failure.
    """
    try:
        rclpy.try_shutdown(context=context)
    except RuntimeError:
        if (context or rclpy.get_default_context()).ok():
            raise
