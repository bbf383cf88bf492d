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
A live view without ROS: ROS 2 topics served over Foxglove's WebSocket protocol (foxglove-sdk).

The node finds the topics of the graph every `discovery_period` (those matching `topics`),
subscribes to each as serialized CDR bytes and serves it on a Foxglove channel with message
encoding cdr and the ros2msg schema of its type (tskf_ros.tools.message_definitions), on
ws://host:port (127.0.0.1:8765 by default). doc/design/foxglove.md says how to open it.
"""

from dataclasses import dataclass
from fnmatch import fnmatchcase
from functools import partial
from typing import Optional

import foxglove
from rcl_interfaces.msg import ParameterType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy
from rclpy.subscription import Subscription

from tskf_ros.bag.message_types import BagTypeError, message_class
from tskf_ros.messages.parameters import descriptor
from tskf_ros.messages.qos import DEFAULT_DEPTH, matching_qos
from tskf_ros.nodes.node_runner import run_node
from tskf_ros.tools.message_definitions import DefinitionError, ros2msg_definition

__all__ = ['BridgeError', 'DEFAULTS', 'FoxgloveBridge', 'main', 'NODE_NAME', 'SUBPROTOCOL']

NODE_NAME = 'foxglove_bridge'
# the WebSocket subprotocol of foxglove-sdk's server: the Foxglove WebSocket protocol
# (foxglove.websocket.v1) under its new name; a client offering only the old name is refused
SUBPROTOCOL = 'foxglove.sdk.v1'
MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODING = 'ros2msg'
# the largest queue depth taken: the nodes' queue_depth bound (rmw's depth is a size_t, and
# a depth of 2**62 is refused only when the first topic is served)
MAX_DEPTH = 100_000
DEFAULTS = {'host': '127.0.0.1', 'port': 8765, 'topics': ['*'], 'discovery_period': 1.0,
            'depth': DEFAULT_DEPTH}
HELP = {
    'host': ('address the WebSocket server listens on (127.0.0.1: this machine only)', None,
             ParameterType.PARAMETER_STRING),
    'port': ('TCP port of the WebSocket server; 0: any free port (logged)', None,
             ParameterType.PARAMETER_INTEGER),
    'topics': ("topics to serve: fully qualified names or fnmatch patterns ('/led/*'); "
               "'*': every topic", None, ParameterType.PARAMETER_STRING_ARRAY),
    'discovery_period': ('s between two looks at the ROS graph for new or gone topics',
                         (0.01, 3600.0), ParameterType.PARAMETER_DOUBLE),
    'depth': (f'queue depth (keep last, 1 to {MAX_DEPTH}) of each subscription; its QoS '
              'matches every publisher of the topic', None, ParameterType.PARAMETER_INTEGER),
}
DESCRIPTION = (
    'Serve ROS 2 topics over the Foxglove WebSocket protocol (foxglove-sdk): open '
    'ws://localhost:8765 in Foxglove (Open connection > Foxglove WebSocket). ROS '
    'parameters (--ros-args -p NAME:=VALUE): ' + '; '.join(
        f'{name} ({DEFAULTS[name]!r}): {text}' for name, (text, _, _) in HELP.items()))


class BridgeError(RuntimeError):
    """The bridge cannot start (bad parameters, the port cannot be bound)."""


@dataclass
class Bridged:
    """One topic served: its type, the Foxglove channel and the ROS subscription."""

    msgtype: str
    channel: foxglove.Channel
    subscription: Subscription


class FoxgloveBridge(Node):
    """Subscribe to the graph's topics and serve them on a Foxglove WebSocket server."""

    def __init__(self, *, context=None, namespace: Optional[str] = None,
                 parameter_overrides: Optional[list] = None) -> None:
        super().__init__(NODE_NAME, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        for name, (text, rng, type_) in HELP.items():
            self.declare_parameter(name, DEFAULTS[name], descriptor(text, rng, type_))
        values = {name: self.get_parameter(name).value for name in HELP}
        if not 0 <= values['port'] <= 65535 or not 1 <= values['depth'] <= MAX_DEPTH:
            raise BridgeError(f'port must be in 0..65535 and depth in 1..{MAX_DEPTH}, got '
                              f"port {values['port']}, depth {values['depth']}")
        self.patterns = list(values['topics'])
        self.depth = values['depth']
        self.bridged: dict[str, Bridged] = {}
        self.skipped: set[tuple[str, str]] = set()   # (topic, type) not served, warned once
        self.foxglove_context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name=NODE_NAME, host=values['host'], port=values['port'],
                context=self.foxglove_context)
        except RuntimeError as exc:
            raise BridgeError(f"cannot serve on {values['host']}:{values['port']}: "
                              f'{exc}') from None
        self.get_logger().info(
            f"Foxglove WebSocket server on ws://{values['host']}:{self.port} (topics "
            f"{', '.join(self.patterns)}): in Foxglove, Open connection > Foxglove WebSocket")
        self.discover()
        self.create_timer(values['discovery_period'], self.discover)

    @property
    def port(self) -> int:
        """Return the port the server listens on (the one chosen when `port` is 0)."""
        return self.server.port

    def wanted(self, topic: str) -> bool:
        """Say whether a topic matches one of the `topics` patterns."""
        return any(fnmatchcase(topic, pattern) for pattern in self.patterns)

    def discover(self) -> None:
        """Serve the new topics that have a publisher; stop serving those that lost theirs."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self.bridged or not self.wanted(topic) \
                    or self.count_publishers(topic) == 0:
                continue
            if len(types) != 1:
                self._skip(topic, ' or '.join(types), 'published with more than one type')
                continue
            try:
                self.bridged[topic] = self._serve(topic, types[0])
            except (BagTypeError, DefinitionError) as exc:
                self._skip(topic, types[0], str(exc))
        for topic in [t for t in self.bridged if self.count_publishers(t) == 0]:
            self._stop_serving(topic)
            self.get_logger().info(f'{topic} has no publisher any more: no longer served')

    def _skip(self, topic: str, msgtype: str, why: str) -> None:
        if (topic, msgtype) not in self.skipped:
            self.skipped.add((topic, msgtype))
            self.get_logger().warning(f'not serving {topic} ({msgtype}): {why}')

    def _serve(self, topic: str, msgtype: str) -> Bridged:
        cls = message_class(msgtype)
        schema = foxglove.Schema(name=msgtype, encoding=SCHEMA_ENCODING,
                                 data=ros2msg_definition(msgtype).encode('utf-8'))
        channel = foxglove.Channel(topic, schema=schema, message_encoding=MESSAGE_ENCODING,
                                   context=self.foxglove_context)
        qos = matching_qos([i.qos_profile for i in self.get_publishers_info_by_topic(topic)],
                           history=HistoryPolicy.KEEP_LAST, depth=self.depth)
        subscription = self.create_subscription(
            cls, topic, partial(self._forward, channel), qos, raw=True)
        self.get_logger().info(f'serving {topic} ({msgtype})')
        return Bridged(msgtype, channel, subscription)

    def _forward(self, channel: foxglove.Channel, data: bytes) -> None:
        channel.log(data, log_time=self.get_clock().now().nanoseconds)

    def _stop_serving(self, topic: str) -> None:
        bridged = self.bridged.pop(topic)
        self.destroy_subscription(bridged.subscription)
        bridged.channel.close()

    def destroy_node(self) -> None:
        """Close every channel and stop the server, then destroy the node."""
        for topic in list(self.bridged):
            self._stop_serving(topic)
        self.server.stop()
        super().destroy_node()


def main(args: Optional[list] = None) -> None:
    """Run the bridge until Ctrl-C or shutdown."""
    run_node(FoxgloveBridge, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(BridgeError,), args=args)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
