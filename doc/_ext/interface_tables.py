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

"""Sphinx extension: a node's topics, services and diagnostic tasks, from node_interfaces."""

from pathlib import Path
from typing import Optional

from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

from doc_tables import paragraph, table
from tskf_ros.messages import diagnostic_tasks, interface_spec, node_interfaces
from tskf_ros.messages.interface_spec import (DiagnosticTask, NodeInterface,
                                              PARAMETER_SERVICES, STANDARD_TOPICS,
                                              TYPE_DESCRIPTION_SERVICE)
from tskf_ros.messages.node_interfaces import interface

TOPIC_HEADER = ('topic', 'dir', 'type', 'content', 'QoS')
TOPIC_WIDTHS = (18, 5, 20, 40, 17)
SERVICE_HEADER = ('service', 'type', 'what it does')
SERVICE_WIDTHS = (25, 25, 50)
LEVEL_HEADER = ('level', 'message', 'when')
LEVEL_WIDTHS = (10, 30, 60)
KEY_HEADER = ('keys', 'meaning')
KEY_WIDTHS = (40, 60)
# the modules a table is read from: a page is rebuilt when one changes
SOURCES = (interface_spec, diagnostic_tasks, node_interfaces)


class InterfaceDirective(SphinxDirective):
    """
    A directive whose argument names a node; its page depends on the declaration.

    In a MyST page ```{topic-table} timescale_estimator``` (or service-table,
    diagnostic-table) renders the node's declaration in tskf_ros.messages.node_interfaces.
    """

    required_arguments = 1
    has_content = False

    def declared(self, node: str = '') -> NodeInterface:
        """Return the declared interface of node (the argument's), noting its modules."""
        for module in SOURCES:
            self.env.note_dependency(str(Path(module.__file__)))
        return interface(node or self.arguments[0])


def _code(text: str) -> nodes.literal:
    return nodes.literal(text, text)


class TopicTable(InterfaceDirective):
    """Render the topics of the node named by the argument."""

    def run(self) -> list:
        """Return the table node."""
        rows = []
        for t in self.declared().topics:
            kind = t.msg_type + (f' (default; the `{t.type_parameter}` parameter names it)'
                             if t.type_parameter else '')
            content = t.content + (f' ({t.provided_by})' if t.provided_by else '')
            rows.append((_code(t.name), t.direction, kind, content, t.qos))
        rows.append((', '.join(f'`{t.name}`' for t in STANDARD_TOPICS), 'out',
                     ', '.join(t.msg_type for t in STANDARD_TOPICS),
                     "the log and the parameter changes (rclpy), every node's", ''))
        return [table(TOPIC_HEADER, TOPIC_WIDTHS, rows, 'topic-table')]


class ServiceTable(InterfaceDirective):
    """Render the services of the node named by the argument, rclpy's parameters last."""

    def run(self) -> list:
        """Return the table node."""
        rows: list = [(_code(s.name), s.srv_type, s.content
                       + (f' ({s.provided_by})' if s.provided_by else ''))
                      for s in self.declared().services]
        rows.append((', '.join(f'`{s.name}`' for s in PARAMETER_SERVICES),
                     'rcl_interfaces/srv/*',
                     "rclpy's parameter services (`ros2 param`), every node's"))
        t = TYPE_DESCRIPTION_SERVICE
        rows.append((_code(t.name), t.srv_type, "the types the node uses (rclpy), every node's"))
        return [table(SERVICE_HEADER, SERVICE_WIDTHS, rows, 'service-table')]


class DiagnosticTable(InterfaceDirective):
    """
    Render diagnostic tasks of the nodes named by the arguments: status, levels, keys.

    Options: `:tasks:` the task names to show (comma-separated; default every task), and
    `:levels-only:` to leave the keys out.  A task several of the nodes share (the same
    declaration) is shown once, under each status name that publishes it::

        ```{diagnostic-table} timescale_estimator alignment
        :tasks: input frequency
        ```
    """

    optional_arguments = 9
    option_spec = {'tasks': directives.unchanged_required, 'levels-only': directives.flag}

    def run(self) -> list:
        """Return, per task, a paragraph naming its statuses, its levels and its keys."""
        wanted = ([name.strip() for name in self.options['tasks'].split(',')]
                  if 'tasks' in self.options else None)
        shown = shared_tasks([self.declared(node) for node in self.arguments], wanted)
        missing = set(wanted or ()) - {task.name for task, _ in shown}
        if missing:
            raise self.error(f'no task {sorted(missing)} in {self.arguments}')
        out: list = []
        for task, statuses in shown:
            title = nodes.paragraph(classes=['diagnostic-task'])
            names = nodes.strong()
            for i, status in enumerate(statuses):
                names.extend(([nodes.Text(', ')] if i else []) + [_code(status)])
            title += names
            title += nodes.Text(': ')
            title.extend(paragraph(task.summary).children)
            out.append(title)
            out.append(table(LEVEL_HEADER, LEVEL_WIDTHS,
                             [(level.level, _code(level.message) if level.message else '',
                               level.when) for level in task.levels],
                             'diagnostic-levels'))
            if 'levels-only' not in self.options:
                out.append(table(KEY_HEADER, KEY_WIDTHS,
                                 [(', '.join(f'`{key}`' for key in row.keys), row.meaning)
                                  for row in task.keys], 'diagnostic-keys'))
        return out


def shared_tasks(declared: list[NodeInterface],
                 wanted: Optional[list[str]]) -> list[tuple[DiagnosticTask, list[str]]]:
    """Return the nodes' tasks (those named in wanted, or all), each with its statuses."""
    shown: list[tuple[DiagnosticTask, list[str]]] = []
    for node in declared:
        for task, status in zip(node.diagnostics, node.status_names()):
            if wanted is not None and task.name not in wanted:
                continue
            statuses = next((names for seen, names in shown if seen == task), None)
            if statuses is None:
                shown.append((task, [status]))
            else:
                statuses.append(status)
    return shown


def setup(app: Sphinx) -> dict:
    """Register the directives."""
    app.add_directive('topic-table', TopicTable)
    app.add_directive('service-table', ServiceTable)
    app.add_directive('diagnostic-table', DiagnosticTable)
    return {'parallel_read_safe': True, 'parallel_write_safe': True, 'version': '1'}
