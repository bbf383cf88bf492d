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
