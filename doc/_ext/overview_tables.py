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

"""Sphinx extension: the overview tables of every node's interface and diagnostic tasks."""

from itertools import groupby
from pathlib import Path
import posixpath

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

from doc_tables import bullets, Cell, table
from interface_tables import SOURCES
from tskf_ros.messages.interface_spec import IN, OUT, Service, Topic
from tskf_ros.messages.node_interfaces import INTERFACES

NODE_HEADER = ('node', 'what it does', 'in', 'out', 'services')
NODE_WIDTHS = (14, 22, 22, 24, 18)
TASK_HEADER = ('node', 'status on /diagnostics', 'levels', 'what it reports')
TASK_WIDTHS = (16, 24, 14, 46)


def topic_item(t: Topic) -> str:
    """Return a topic as an overview's list item: name, type, when it exists, who makes it."""
    kind = t.msg_type + (f'; `{t.type_parameter}` names another' if t.type_parameter else '')
    only = (' only with some values of ' + ', '.join(f'`{p}`' for p in t.only_with)
            if t.only_with else '')
    by = f' ({t.provided_by})' if t.provided_by else ''
    return f'`{t.name}` ({kind}){only}{by}'


def service_items(services: tuple[Service, ...]) -> list[str]:
    """Return the node's own services one by one; those a library gives, one item each."""
    out = []
    for provider, group in groupby(services, key=lambda s: s.provided_by):
        group = list(group)
        if not provider:
            out += [f'`{s.name}` ({s.srv_type})' for s in group]
        else:
            kinds = ', '.join(dict.fromkeys(s.srv_type for s in group))
            out.append(', '.join(f'`{s.name}`' for s in group) + f' ({kinds}; {provider})')
    return out


class OverviewDirective(SphinxDirective):
    """A directive without argument whose page depends on every node's declaration."""

    has_content = False

    def note_sources(self) -> None:
        """Rebuild the page when a module the table is read from changes (SOURCES)."""
        for module in SOURCES:
            self.env.note_dependency(str(Path(module.__file__)))

    def node_link(self, node: str, anchor: str = '') -> Cell:
        """Return a link to the node's page (doc/nodes/<node>.md), at anchor if given."""
        here = posixpath.dirname(self.env.docname) or '.'
        target = posixpath.relpath(f'nodes/{node}', here) + '.md' + (f'#{anchor}' if anchor
                                                                     else '')
        link, messages = self.parse_inline(f'[{node}]({target})', lineno=self.lineno)
        return nodes.paragraph('', '', *link, *messages)


class NodeOverview(OverviewDirective):
    """Render every node: what it does, the topics in and out with types, its services."""

    def run(self) -> list:
        """Return the table node (class node-overview)."""
        self.note_sources()
        rows = [(self.node_link(name), declared.purpose,
                 bullets([topic_item(t) for t in declared.topics if t.direction == IN]),
                 bullets([topic_item(t) for t in declared.topics if t.direction == OUT]),
                 bullets(service_items(declared.services)))
                for name, declared in INTERFACES.items()]
        return [table(NODE_HEADER, NODE_WIDTHS, rows, 'node-overview')]


class DiagnosticOverview(OverviewDirective):
    """Render every node's diagnostic tasks: status name, levels, what the task reports."""

    def run(self) -> list:
        """Return the table node (class diagnostic-overview)."""
        self.note_sources()
        rows = [(self.node_link(name, 'diagnostics'), f'`{status}`',
                 ', '.join(task.level_names()), task.summary)
                for name, declared in INTERFACES.items()
                for task, status in zip(declared.diagnostics, declared.status_names())]
        return [table(TASK_HEADER, TASK_WIDTHS, rows, 'diagnostic-overview')]


def setup(app: Sphinx) -> dict:
    """Register the directives."""
    app.add_directive('node-overview', NodeOverview)
    app.add_directive('diagnostic-overview', DiagnosticOverview)
    return {'parallel_read_safe': True, 'parallel_write_safe': True, 'version': '1'}
