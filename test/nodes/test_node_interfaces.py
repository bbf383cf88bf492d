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
Each running node has exactly the topics, services and diagnostic tasks its page declares.

The declaration is tskf_ros.messages.node_interfaces (the node pages render it, the
nodes take their names from it).  Each node is started in-process, in a namespace so that
relative and absolute names are told apart, and the ROS graph is asked what it has, as
`ros2 node info` asks: its publishers, subscriptions and services by node, with their
types.  Every declared topic and service must be there with its type and nothing else may
be, but for what rclpy gives every node (/rosout, /parameter_events, the parameter
services, the type description service).  A topic that exists only with some parameters
(only_with) must be absent with the defaults and present with them.  The graph's QoS of
each topic (reliability, durability; discovery carries no depth) must be the one its QoS
summary says.  Then the first
/diagnostics message of the node must carry the declared tasks, in order, and only keys
the tasks declare.
"""

import uuid

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from tskf_ros.messages.interface_spec import (IN, NodeInterface, OUT, STANDARD_SERVICES,
                                              STANDARD_TOPICS, Topic)
from tskf_ros.messages.node_interfaces import INTERFACES
from tskf_ros.testing import NODES, spin_until, start_in_process
from visa_faults import bench

# a namespace of each test's own: the graph may still show the node of an earlier test
# (another participant, being removed) under the same name
NAMESPACE = '/rig_{}'
# every node: diagnostics fast, so that the first message comes at once
FAST = {'diagnostic_updater.period': 0.05}
# the measurement type the estimator is started with when every topic must exist: not the
# default, so that the topic is seen to follow its parameter
OTHER_MEASUREMENT_TYPE = 'sensor_msgs/msg/Temperature'


@pytest.fixture
def executor_kind():
    """Return 'single': the graph and the diagnostics do not depend on the executor."""
    return 'single'


def graph(node: Node) -> dict:
    """Return {'publishers' | 'subscriptions' | 'services': {name: type}} of the node."""
    name, namespace = node.get_name(), node.get_namespace()
    asked = {'publishers': node.get_publisher_names_and_types_by_node,
             'subscriptions': node.get_subscriber_names_and_types_by_node,
             'services': node.get_service_names_and_types_by_node}
    out = {}
    for kind, ask in asked.items():
        found = {}
        for topic, types in ask(name, namespace):
            assert len(types) == 1, f'{topic} has several types: {types}'
            found[topic] = types[0]
        out[kind] = found
    return out


def discovered(node: Node) -> bool:
    """Tell whether the graph shows every publisher, subscription, service the node holds."""
    found = graph(node)
    held = {'publishers': {node.resolve_topic_name(p.topic_name) for p in node.publishers},
            'subscriptions': {node.resolve_topic_name(s.topic_name)
                              for s in node.subscriptions},
            'services': {node.resolve_service_name(s.srv_name) for s in node.services}}
    return all(held[kind] <= set(found[kind]) for kind in held)


def expected(node: Node, declared: NodeInterface, parameters: dict) -> dict:
    """Return the graph the declaration promises for a node started with parameters."""
    out: dict = {'publishers': {}, 'subscriptions': {}, 'services': {}}
    for topic in declared.topics:
        if any(parameters.get(k) != v for k, v in topic.only_with.items()):
            continue
        kind = parameters.get(topic.type_parameter, topic.msg_type) if topic.type_parameter \
            else topic.msg_type
        assert topic.direction in (IN, OUT), topic
        out['publishers' if topic.direction == OUT else 'subscriptions'][
            node.resolve_topic_name(topic.name)] = kind
    for service in declared.services:
        out['services'][node.resolve_service_name(service.name)] = service.srv_type
    return out


def standard(node: Node) -> dict:
    """Return the graph entries rclpy makes for any node (left out of the comparison)."""
    return {'publishers': {t.name: t.msg_type for t in STANDARD_TOPICS}, 'subscriptions': {},
            'services': {node.resolve_service_name(s.name): s.srv_type
                         for s in STANDARD_SERVICES}}


def without_standard(found: dict, node: Node) -> dict:
    """Return the graph with what rclpy gives every node taken out."""
    std = standard(node)
    return {kind: {name: t for name, t in entries.items()
                   if std[kind].get(name) != t}
            for kind, entries in found.items()}


def start(loop, tmp_path, name: str, every_topic: bool, **more) -> tuple[Node, dict]:
    """Start the node in a NAMESPACE (every topic: with only_with's parameters); return it."""
    executor, _, nodes = loop
    declared = INTERFACES[name]
    parameters = {**FAST, **more}
    if every_topic:
        parameters.update(declared.every_topic_parameters())
        if name == 'timescale_estimator':
            parameters['measurement_type'] = OTHER_MEASUREMENT_TYPE
    if name == 'power_meter_driver':        # the simulated PM100: a meter that answers
        parameters.update(backend=bench(tmp_path).backend, rate=50.0)
    node = start_in_process(name, executor.context, executor, parameters=parameters,
                            namespace=NAMESPACE.format(uuid.uuid4().hex[:8]))
    nodes.append(node)
    return node, parameters


def test_every_node_has_a_declared_interface():
    assert sorted(INTERFACES) == sorted(NODES)


@pytest.mark.parametrize('every_topic', [False, True], ids=['defaults', 'every_topic'])
@pytest.mark.parametrize('name', sorted(INTERFACES))
def test_the_running_node_has_the_declared_topics_and_services(loop, tmp_path, name,
                                                               every_topic):
    executor = loop[0]
    node, parameters = start(loop, tmp_path, name, every_topic)
    want = expected(node, INTERFACES[name], parameters)
    # the graph shows the node's entities once it has discovered them: wait until it
    # shows those the node holds (rclpy's lists; not the ones made in C, which come along)
    spin_until(executor, lambda: discovered(node),
               what=lambda: f'the graph to show what {name} holds: has {graph(node)}')
    found = without_standard(graph(node), node)
    for kind in want:
        assert found[kind] == want[kind], f'{name} {kind}'
    # the QoS the graph shows (reliability, durability: DDS discovery carries no depth)
    for topic in INTERFACES[name].topics:
        if not topic.only_with or every_topic:
            assert endpoint_qos(node, topic) == declared_qos(topic), f'{name} {topic.name}'


def declared_qos(topic: Topic) -> tuple:
    """Return the (reliability, durability) a topic's QoS summary says."""
    reliability = (ReliabilityPolicy.RELIABLE if topic.qos.startswith('reliable') else
                   ReliabilityPolicy.BEST_EFFORT if topic.qos.startswith('best effort')
                   else None)
    assert reliability is not None, f'{topic.name}: QoS {topic.qos!r} names no reliability'
    durability = (DurabilityPolicy.TRANSIENT_LOCAL if 'transient local' in topic.qos
                  else DurabilityPolicy.VOLATILE)
    return reliability, durability


def endpoint_qos(node: Node, topic: Topic) -> tuple:
    """Return the (reliability, durability) of the node's endpoint of a topic in the graph."""
    ask = (node.get_publishers_info_by_topic if topic.direction == OUT
           else node.get_subscriptions_info_by_topic)
    mine = [info.qos_profile for info in ask(node.resolve_topic_name(topic.name))
            if (info.node_name, info.node_namespace) == (node.get_name(),
                                                         node.get_namespace())]
    assert len(mine) == 1, f'{topic.name}: {len(mine)} endpoints of the node'
    return mine[0].reliability, mine[0].durability


def first_diagnostics(loop, node: Node) -> DiagnosticArray:
    """Return the first /diagnostics message of the node that a listener receives."""
    executor, client, _ = loop
    got: list = []

    def on_diagnostics(msg: DiagnosticArray) -> None:
        if any(s.name.startswith(f'{node.get_name()}: ') for s in msg.status):
            got.append(msg)

    sub = client.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    try:
        spin_until(executor, lambda: bool(got), what=f'/diagnostics of {node.get_name()}')
    finally:
        client.destroy_subscription(sub)
    return got[0]


@pytest.mark.parametrize('name', sorted(INTERFACES))
def test_the_running_node_publishes_the_declared_diagnostic_tasks(loop, tmp_path, name):
    node, _ = start(loop, tmp_path, name, every_topic=False)
    declared = INTERFACES[name]
    msg = first_diagnostics(loop, node)
    assert [s.name for s in msg.status] == declared.status_names(node.get_name())
    assert_keys_declared(declared, msg)


def assert_keys_declared(declared: NodeInterface, msg: DiagnosticArray) -> None:
    """Assert that every key of every status of msg is one its task declares."""
    for status in msg.status:
        task = declared.task(status.name)
        undeclared = [kv.key for kv in status.values if not task.allows(kv.key)]
        assert not undeclared, f'{status.name}: keys not declared: {undeclared}'


def test_an_unconfigured_driver_publishes_a_declared_task_with_declared_keys(loop, tmp_path):
    # no meter open: only 'power meter', WARN, its one key the lifecycle state
    node, _ = start(loop, tmp_path, 'power_meter_driver', every_topic=False, autostart=False)
    declared = INTERFACES['power_meter_driver']
    msg = first_diagnostics(loop, node)
    assert [s.name for s in msg.status] == [f'{node.get_name()}: power meter']
    assert [kv.key for kv in msg.status[0].values] == ['Lifecycle state']
    assert_keys_declared(declared, msg)


@pytest.mark.parametrize('name', ['alignment', 'led_link_simulator'])
def test_two_axes_have_the_declared_topics_services_and_diagnostic_keys(loop, tmp_path, name):
    # axes 2 (a pan-tilt mount) changes the messages' lengths, not the graph
    executor = loop[0]
    node, parameters = start(loop, tmp_path, name, every_topic=False, axes=2)
    want = expected(node, INTERFACES[name], parameters)
    spin_until(executor, lambda: discovered(node),
               what=lambda: f'the graph to show what {name} holds: has {graph(node)}')
    found = without_standard(graph(node), node)
    for kind in want:
        assert found[kind] == want[kind], f'{name} {kind}'
    msg = first_diagnostics(loop, node)
    assert [s.name for s in msg.status] == INTERFACES[name].status_names(node.get_name())
    assert_keys_declared(INTERFACES[name], msg)
