"""A node's periodic one-line INFO status: rate in, gaps, last estimate, resets."""

from typing import Callable, Optional

from rclpy.node import Node
from rclpy.timer import Timer

from tskf_ros.core.units import NS


class StatusLine:
    """Log `text(rate)` at INFO every period seconds (0: never), rate = count() per second."""

    def __init__(self, node: Node, period: float, count: Callable[[], int],
                 text: Callable[[float], str]) -> None:
        self.node, self.count, self.text = node, count, text
        self.timer: Optional[Timer] = None
        self.logged = 0             # lines logged so far
        self.retime(period)

    def retime(self, period: float) -> None:
        """Log every period seconds from now on (0: stop)."""
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None
        self.last = (self.count(), self.node.get_clock().now().nanoseconds)
        if period > 0:
            self.timer = self.node.create_timer(period, self.log)

    def log(self) -> str:
        """Log (and return) the status line now."""
        count, now = self.count(), self.node.get_clock().now().nanoseconds
        elapsed = (now - self.last[1]) / NS
        rate = (count - self.last[0]) / elapsed if elapsed > 0 else 0.0
        self.last = (count, now)
        line = self.text(rate)
        self.node.get_logger().info(line)
        self.logged += 1
        return line
