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

"""Which sections of a parameter file apply to a node: parameters_for_node against rclpy."""

import rclpy
from rclpy.context import Context
from rclpy.node import Node

from tskf_ros.messages.parameters import parameters_for_node, section_applies

# section keys rcl accepts, each with its own parameter p<i>; nested namespaces too
KEYS = ['n', '/n', '/**', '/**/n', '/ref/n', 'ref/n', '/*/n', '/ref/*', '/ref/**',
        '/**/ref/n', '*', '/*', '/**/*', '/a/**/n', '/a/*/n', '/**/a/**/n', 'other',
        '/ref/other', '/a/ref/n']
NAMESPACES = ['/', '/ref', '/a/ref', '/a/b/ref']


def write_file(path):
    """Write one section per key (p<i>) and the nested-namespace sections."""
    lines = [f'"{key}":\n  ros__parameters:\n    p{i}: 1\n' for i, key in enumerate(KEYS)]
    lines += ['ref:\n  n:\n    ros__parameters:\n      ref_n: 1\n',
              '/a/**:\n  n:\n    ros__parameters:\n      a_any_n: 1\n',
              'a:\n  ref/n:\n    ros__parameters:\n      group:\n        a_ref_n: 1\n']
    path.write_text(''.join(lines))


def test_the_sections_that_apply_are_the_ones_rclpy_applies(tmp_path):
    path = tmp_path / 'params.yaml'
    write_file(path)
    names = [f'p{i}' for i in range(len(KEYS))] + ['ref_n', 'a_any_n', 'group.a_ref_n']
    for namespace in NAMESPACES:
        context = Context()
        rclpy.init(context=context, args=['--ros-args', '--params-file', str(path),
                                          '-r', f'__ns:={namespace}'])
        try:
            node = Node('n', context=context)
            try:
                applied = {name for name in names
                           if node.declare_parameter(name, 0).value == 1}
                fqn = node.get_fully_qualified_name()
            finally:
                node.destroy_node()
        finally:
            context.try_shutdown()
        assert parameters_for_node(path, fqn) == applied, namespace
        assert applied        # '/**' applies everywhere: the comparison is not vacuous


def test_wildcards_by_hand():
    assert section_applies('/**', '/n') and section_applies('/**/n', '/a/b/n')
    assert section_applies('n', '/n') and not section_applies('n', '/ref/n')
    assert section_applies('/*/n', '/ref/n') and not section_applies('/*/n', '/a/ref/n')
    assert not section_applies('/**/m', '/a/n')
    assert not section_applies('/r.f/n', '/ref/n')      # tokens are literal, not regexes
