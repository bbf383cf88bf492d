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

"""The declared ROS interface of a node: topics, services and diagnostic tasks, as data."""

from dataclasses import dataclass, field
import re
from typing import Any, Mapping

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ['DiagnosticTask', 'IN', 'KeyRow', 'LevelRow', 'LIFECYCLE', 'LIFECYCLE_SERVICES',
           'NodeInterface', 'OUT', 'PARAMETER_SERVICES', 'qos_summary', 'RCLPY', 'Service',
           'STANDARD_SERVICES', 'STANDARD_TOPICS', 'Topic', 'TRANSITION_EVENT',
           'TYPE_DESCRIPTION_SERVICE']

IN, OUT = 'in', 'out'
# who offers a service or topic other than the node's own code
RCLPY, LIFECYCLE = 'rclpy', 'rclpy.lifecycle'


@dataclass(frozen=True)
class Topic:
    """
    A topic a node publishes (OUT) or subscribes to (IN).

    name is relative (resolved in the node's namespace) unless it starts with '/'.  A topic
    that exists only with some parameters names them in only_with ({parameter: a value
    that makes it exist}); one whose type is a parameter names it in type_parameter.
    """

    name: str
    msg_type: str
    direction: str
    qos: str
    content: str
    only_with: Mapping[str, Any] = field(default_factory=dict, hash=False)
    type_parameter: str = ''
    provided_by: str = ''


@dataclass(frozen=True)
class Service:
    """A service a node offers: name (relative, or '~/...' private), type, what it does."""

    name: str
    srv_type: str
    content: str
    provided_by: str = ''        # '' the node's code, else RCLPY or LIFECYCLE


@dataclass(frozen=True)
class KeyRow:
    """Keys of a diagnostic task that go together; '<reason>' stands for any word."""

    keys: tuple[str, ...]
    meaning: str

    def patterns(self) -> list[re.Pattern]:
        """Return a regular expression matching each key (a '<...>' placeholder: any text)."""
        return [re.compile('^' + '.+'.join(re.escape(part) for part in
                                           re.split(r'<[a-z_]+>', key)) + '$')
                for key in self.keys]


@dataclass(frozen=True)
class LevelRow:
    """One level a task can report: DiagnosticStatus's name (OK, WARN, ERROR), when, message."""

    level: str
    when: str
    message: str = ''            # the status message, where it is a fixed text


@dataclass(frozen=True)
class DiagnosticTask:
    """A task of the node's /diagnostics: status '<node>: <name>', its levels and keys."""

    name: str
    summary: str
    levels: tuple[LevelRow, ...]
    keys: tuple[KeyRow, ...]

    def allows(self, key: str) -> bool:
        """Tell whether a key a status carries is one this task declares."""
        return any(p.match(key) for row in self.keys for p in row.patterns())

    def level_names(self) -> list[str]:
        """Return the levels the task can report, each once, in the order declared."""
        return list(dict.fromkeys(row.level for row in self.levels))


@dataclass(frozen=True)
class NodeInterface:
    """Everything a node offers on the graph besides its parameters (config/schema)."""

    node: str
    topics: tuple[Topic, ...]
    services: tuple[Service, ...]
    diagnostics: tuple[DiagnosticTask, ...]
    note: str = ''
    purpose: str = ''            # what the node does, in one line (doc/nodes/index.md)

    def status_names(self, node_name: str = '') -> list[str]:
        """Return the /diagnostics status names, '<node>: <task>', in publishing order."""
        return [f'{node_name or self.node}: {task.name}' for task in self.diagnostics]

    def task(self, status_name: str) -> DiagnosticTask:
        """Return the task of a status name '<node>: <task>' (KeyError if undeclared)."""
        wanted = status_name.partition(': ')[2]
        for task in self.diagnostics:
            if task.name == wanted:
                return task
        raise KeyError(status_name)

    def every_topic_parameters(self) -> dict:
        """Return parameter values with which every declared topic exists."""
        values: dict = {}
        for topic in self.topics:
            values.update(topic.only_with)
        return values


def qos_summary(qos: QoSProfile) -> str:
    """Return a QoS profile in words: 'reliable, keep last 10' (durability when latched)."""
    reliability = {ReliabilityPolicy.RELIABLE: 'reliable',
                   ReliabilityPolicy.BEST_EFFORT: 'best effort'}.get(qos.reliability,
                                                                     'system default')
    history = (f'keep last {qos.depth}' if qos.history == HistoryPolicy.KEEP_LAST
               else 'keep all' if qos.history == HistoryPolicy.KEEP_ALL
               else f'depth {qos.depth}')
    latched = ', transient local' if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL else ''
    return f'{reliability}, {history}{latched}'


# rclpy's parameter services of every node (ros2 param talks to them)
PARAMETER_SERVICES = tuple(
    Service(f'~/{name}', f'rcl_interfaces/srv/{kind}', 'the parameters (rclpy)', RCLPY)
    for name, kind in (('describe_parameters', 'DescribeParameters'),
                       ('get_parameter_types', 'GetParameterTypes'),
                       ('get_parameters', 'GetParameters'),
                       ('list_parameters', 'ListParameters'),
                       ('set_parameters', 'SetParameters'),
                       ('set_parameters_atomically', 'SetParametersAtomically')))

# a lifecycle node's services (rclpy.lifecycle.LifecycleNode: ros2 lifecycle talks to them)
LIFECYCLE_SERVICES = tuple(
    Service(f'~/{name}', f'lifecycle_msgs/srv/{kind}', content, LIFECYCLE)
    for name, kind, content in (
        ('change_state', 'ChangeState', 'trigger a transition (configure, activate, ...)'),
        ('get_state', 'GetState', 'the current state'),
        ('get_available_states', 'GetAvailableStates', 'every state of the state machine'),
        ('get_available_transitions', 'GetAvailableTransitions',
         'the transitions possible from the current state'),
        ('get_transition_graph', 'GetAvailableTransitions', 'every transition')))

# rclpy's type description service of every node (REP 2011)
TYPE_DESCRIPTION_SERVICE = Service(
    '~/get_type_description', 'type_description_interfaces/srv/GetTypeDescription',
    'the descriptions of the types the node uses (rclpy)', RCLPY)
# what rclpy gives every node besides: services, and topics (absolute names)
STANDARD_SERVICES = PARAMETER_SERVICES + (TYPE_DESCRIPTION_SERVICE,)
STANDARD_TOPICS = (
    Topic('/rosout', 'rcl_interfaces/msg/Log', OUT, 'reliable, keep last 1000, transient '
          'local', "the node's log (rclpy)", provided_by=RCLPY),
    Topic('/parameter_events', 'rcl_interfaces/msg/ParameterEvent', OUT,
          'reliable, keep last 1000', 'every parameter change (rclpy)', provided_by=RCLPY))

TRANSITION_EVENT = Topic(
    '~/transition_event', 'lifecycle_msgs/msg/TransitionEvent', OUT, 'reliable, keep last 10',
    'every transition taken: start state, goal state, transition', provided_by=LIFECYCLE)
