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
A check a node makes once, a few seconds after it starts, and the warnings it gives.

A node that waits on something that never comes (a topic nobody publishes, a /clock that
never ticks) would otherwise stand still in silence.  A StartupWatch runs `problems()`
once, `delay` s after start on the steady clock (which runs whether or not /clock does),
logs each problem as one warning and keeps them in `warnings`.  InputWatch and ClockWatch
are the two the nodes make.
"""

from typing import Optional

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer


class StartupWatch:
    """Run `problems()` once, `delay` s after start (steady clock); warn once per problem."""

    def __init__(self, node: Node, delay: float, *, armed: bool = True) -> None:
        self.node = node
        self.delay = delay
        self.warnings: list[str] = []
        self.checked = False
        self.timer: Optional[Timer] = (
            node.create_timer(delay, self.check, clock=Clock(clock_type=ClockType.STEADY_TIME))
            if armed else None)

    def problems(self) -> list[str]:
        """Return what is wrong now, one sentence each (subclasses)."""
        raise NotImplementedError

    def check(self) -> None:
        """Look once (the timer's call or a test's): log and keep each problem found."""
        if self.checked:
            return
        self.checked = True
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None
        for warning in self.problems():
            self.warnings.append(warning)
            self.node.get_logger().warning(warning)
