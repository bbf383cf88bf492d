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
An input topic nobody publishes is named, once, with the remap to try.

A subscriber on the wrong topic name waits in silence.  NO_PUBLISHER_DELAY s after start
(steady clock) each input without a publisher is named in one warning, with its type and,
if another topic of that type has a publisher, that topic as the remap to try.
"""

from typing import Any, Optional, Sequence

from rclpy.node import Node

from tskf_ros.nodes.startup_watch import StartupWatch

# s (steady clock) after which an input topic with no publisher is named in one warning
NO_PUBLISHER_DELAY = 5.0


def type_name(msg_type: type) -> str:
    """Return a message class's ROS type name, 'sensor_msgs/msg/Illuminance'."""
    return f'{msg_type.__module__.split(".")[0]}/msg/{msg_type.__name__}'


class InputWatch(StartupWatch):
    """Warn once per input topic that still has no publisher NO_PUBLISHER_DELAY s after start."""

    def __init__(self, node: Node, subscriptions: Sequence[Any],
                 delay: Optional[float] = None) -> None:
        self.subscriptions = list(subscriptions)
        super().__init__(node, NO_PUBLISHER_DELAY if delay is None else delay)

    def problems(self) -> list[str]:
        """Return one sentence per input topic nobody publishes (and the likely remap)."""
        topics = self.node.get_topic_names_and_types()
        found = []
        for sub in self.subscriptions:
            if self.node.count_publishers(sub.topic_name) > 0:
                continue
            kind = type_name(sub.msg_type)
            others = [name for name, types in topics if kind in types and
                      name != sub.topic_name and self.node.count_publishers(name) > 0]
            hint = (f'; {others[0]} has a publisher of that type: try '
                    f'--ros-args -r {sub.topic_name}:={others[0]}' if others else '')
            found.append(f'no publisher on {sub.topic_name} ({kind}) after '
                         f'{self.delay:g} s: nothing to filter yet{hint}')
        return found
