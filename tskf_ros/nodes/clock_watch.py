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
A node on use_sim_time whose clock never starts says so, once, instead of standing still.

With use_sim_time true the node clock reads 0 until the first /clock message: a timer on
it never fires (a simulator publishes nothing, no /diagnostics, no status line) and
nothing is stamped.  Without a warning that is a node that silently does nothing.  The
check runs NO_CLOCK_DELAY s after start on the steady clock, which runs whatever /clock
does.
"""

from typing import Optional

from rclpy.node import Node

from tskf_ros.nodes.startup_watch import StartupWatch

# s (steady clock) after which a node on use_sim_time whose clock still reads 0 says so
NO_CLOCK_DELAY = 5.0
CLOCK_TOPIC = '/clock'


class ClockWatch(StartupWatch):
    """Warn once if use_sim_time is true and the clock still reads 0 after the delay."""

    def __init__(self, node: Node, delay: Optional[float] = None) -> None:
        super().__init__(node, NO_CLOCK_DELAY if delay is None else delay,
                         armed=bool(node.get_parameter('use_sim_time').value))

    @property
    def sim_time(self) -> bool:
        """Return whether the node runs on use_sim_time now."""
        return bool(self.node.get_parameter('use_sim_time').value)

    def problems(self) -> list[str]:
        """Return that the clock has not started, and the likely reason (or nothing)."""
        if not self.sim_time or self.node.get_clock().now().nanoseconds > 0:
            return []
        why = (f'{CLOCK_TOPIC} has a publisher, but no message has come'
               if self.node.count_publishers(CLOCK_TOPIC) > 0
               else f'nobody publishes {CLOCK_TOPIC}')
        return [f'use_sim_time is true and the clock still reads 0 after {self.delay:g} s '
                f'({why}): timers do not fire and nothing is stamped; play a bag with '
                "'ros2 bag play --clock', run a simulator that publishes "
                f'{CLOCK_TOPIC}, or set use_sim_time:=false']
