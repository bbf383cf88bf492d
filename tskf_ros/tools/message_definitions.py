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
The ros2msg definition of an installed message type, as rosbag2 stores it in MCAP schemas.

rosbag2's message definition encoding (docs/message_definition_encoding.md of ros2/rosbag2):
the type's own .msg text first, then, for every type it depends on (its field types, and
theirs), a line of 80 '=', a line 'MSG: <package>/<Type>' and that type's .msg text. Each
dependency appears once, depth first, the dependencies of one definition in sorted order,
as rosbag2_cpp's LocalMessageDefinitionSource writes them. The .msg files are those the
rosidl packages install into share/<package>/msg/ of their ament prefix.
"""

from pathlib import Path
import re
import sys
from typing import Iterator

from ament_index_python.packages import get_package_share_directory, PackageNotFoundError

__all__ = ['DefinitionError', 'msg_dependencies', 'ros2msg_definition', 'SEPARATOR',
           'share_directory']

SEPARATOR = '=' * 80
# the primitive types of the .msg grammar (rosidl_adapter), wstring included
PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'))
# package/msg/Type or package/Type, as topic types and field types name them
TYPE_NAME = re.compile(r'(?P<package>[a-zA-Z][a-zA-Z0-9_]*)/(?:msg/)?(?P<name>[A-Z][A-Za-z0-9]*)')
# the type of a field or constant line: the first word, less an array suffix ([], [3],
# [<=3]) and a string bound (string<=8)
FIELD_TYPE = re.compile(r'\s*(?P<type>[A-Za-z][A-Za-z0-9_/]*)(?:<=\d+)?(?:\[[^\]]*\])?\s')
# a definition cannot be deeper than this (a cycle in broken .msg files ends here)
MAX_DEPTH = 100
# the ament resource index marker of an installed package, below a prefix
INDEX_MARKER = Path('share', 'ament_index', 'resource_index', 'packages')


class DefinitionError(LookupError):
    """A type whose definition cannot be made (its package or .msg file is not installed)."""


def share_directory(package: str) -> Path:
    """
    Return share/<package> of an installed ROS package.

    The ament index of $AMENT_PREFIX_PATH first (a sourced workspace), then this
    interpreter's prefix: the ROS wheels of a venv install their ament index there.
    """
    try:
        return Path(get_package_share_directory(package))
    except (OSError, PackageNotFoundError):     # no $AMENT_PREFIX_PATH, or not in it
        pass
    prefix = Path(sys.prefix)
    if (prefix / INDEX_MARKER / package).is_file():
        return prefix / 'share' / package
    raise DefinitionError(f'package {package} is not installed (not in the ament index of '
                          f'$AMENT_PREFIX_PATH nor of {prefix})')


def _split(msgtype: str) -> tuple:
    match = TYPE_NAME.fullmatch(msgtype)
    if match is None:
        raise DefinitionError(f'{msgtype!r} is not a message type name (package/msg/Type)')
    return match['package'], match['name']


def msg_text(msgtype: str) -> str:
    """Return the installed .msg text of a type ('pkg/msg/Type' or 'pkg/Type')."""
    package, name = _split(msgtype)
    path = share_directory(package) / 'msg' / f'{name}.msg'
    try:
        return path.read_text(encoding='utf-8')
    except OSError:
        raise DefinitionError(f'{msgtype} has no .msg definition ({path} is missing)') from None


def msg_dependencies(text: str, package: str) -> list:
    """
    Return the message types a .msg text uses, sorted, each as 'package/Type'.

    A field type without a package is of the definition's own package.
    """
    found = set()
    for line in text.splitlines():
        match = FIELD_TYPE.match(line)
        if match is None or match['type'] in PRIMITIVES:
            continue
        type_ = match['type']
        found.add(type_ if '/' in type_ else f'{package}/{type_}')
    return sorted(found)


def _blocks(msgtype: str, seen: set, depth: int) -> Iterator[str]:
    if depth > MAX_DEPTH:
        raise DefinitionError(f'the definition of {msgtype} nests deeper than {MAX_DEPTH}')
    text = msg_text(msgtype)
    yield text
    for dependency in msg_dependencies(text, _split(msgtype)[0]):
        package, name = _split(dependency)
        if (package, name) in seen:
            continue
        seen.add((package, name))
        yield f'\n{SEPARATOR}\nMSG: {dependency}\n'
        yield from _blocks(dependency, seen, depth + 1)


def ros2msg_definition(msgtype: str) -> str:
    """Return the ros2msg (rosbag2) definition of an installed type ('std_msgs/msg/Header')."""
    return ''.join(_blocks(msgtype, {_split(msgtype)}, 0))
