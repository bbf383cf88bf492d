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

"""Docutils tables for the Sphinx directives of doc/_ext: a header, rows of cells."""

from typing import Sequence, Union

from docutils import nodes

# a cell: plain text (`code` in backticks becomes a literal), a paragraph, a bullet list or
# an inline node
Cell = Union[str, nodes.Node]


def inline(text: str) -> list[nodes.Node]:
    """Return text as inline nodes: each `...` in backticks a literal, the rest text."""
    parts = text.split('`')
    return [nodes.literal(part, part) if i % 2 else nodes.Text(part)
            for i, part in enumerate(parts) if part]


def paragraph(text: str) -> nodes.paragraph:
    """Return a paragraph of inline text (see inline)."""
    return nodes.paragraph('', '', *inline(text))


def bullets(items: Sequence[str]) -> Cell:
    """Return a bullet list of inline texts (see inline), or '' for no item."""
    if not items:
        return ''
    out = nodes.bullet_list()
    for text in items:
        item = nodes.list_item()
        item += paragraph(text)
        out += item
    return out


def _row(cells: Sequence[Cell]) -> nodes.row:
    row = nodes.row()
    for content in cells:
        entry = nodes.entry()
        if isinstance(content, (nodes.paragraph, nodes.bullet_list)):
            entry += content
        elif isinstance(content, str):
            entry += paragraph(content)
        else:
            entry += nodes.paragraph('', '', content)
        row += entry
    return row


def table(header: Sequence[str], widths: Sequence[int], rows: Sequence[Sequence[Cell]],
          css_class: str) -> nodes.table:
    """Return a table node of the header and rows, with css_class (tests find it by it)."""
    out = nodes.table(classes=[css_class])
    group = nodes.tgroup(cols=len(header))
    out += group
    group.extend(nodes.colspec(colwidth=w) for w in widths)
    head = nodes.thead()
    head += _row([nodes.Text(h) for h in header])
    group += head
    body = nodes.tbody()
    for cells in rows:
        body += _row(cells)
    group += body
    return out
