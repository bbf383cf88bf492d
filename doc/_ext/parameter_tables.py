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
Sphinx extension: the `parameter-table` directive renders a node's parameters from its schema.

In a MyST page::

    ```{parameter-table} timescale_estimator
    ```

becomes the table of config/schema/timescale_estimator.yaml (name, type, default, range,
read-only, description), read through tskf_ros.messages.parameter_schema, so a node page
cannot drift from the parameters the node declares.  A page is rebuilt when its schema
changes.
"""

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

from doc_tables import table
from tskf_ros.messages.parameter_schema import load_schema, schema_path

HEADER = ('parameter', 'type', 'default', 'range', 'read-only', 'description')
WIDTHS = (16, 8, 12, 14, 6, 44)


class ParameterTable(SphinxDirective):
    """Render the parameter table of the node named by the argument."""

    required_arguments = 1
    has_content = False

    def run(self) -> list:
        """Return the table node."""
        node_name = self.arguments[0]
        schema = load_schema(node_name)
        self.env.note_dependency(str(schema_path(node_name)))
        return [table(HEADER, WIDTHS, [
            (nodes.literal(row.name, row.name), nodes.Text(row.type_name),
             nodes.literal(row.default, row.default), nodes.Text(row.constraints),
             nodes.Text('yes' if row.read_only else ''), nodes.Text(row.description))
            for row in schema.table_rows()], 'parameter-table')]


def setup(app: Sphinx) -> dict:
    """Register the directive."""
    app.add_directive('parameter-table', ParameterTable)
    return {'parallel_read_safe': True, 'parallel_write_safe': True, 'version': '1'}
