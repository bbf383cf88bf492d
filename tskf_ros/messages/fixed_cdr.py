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
Fixed-layout CDR decoding (XCDR1, little endian), without rosbags: what a node reads raw.

A type of fixed layout is an optional std_msgs/Header (its frame_id the only
variable-length part) then fixed-size base fields.  `layout_decoder` reads the fields
of such a layout straight from the bytes (tskf_ros.bag.cdr takes the layout from
rosbags' type definitions, `rclpy_layout` from rclpy's message class).
"""

import operator
import struct
from typing import Any, Callable, Optional, Sequence

from tskf_ros.core.units import NS

STAMP_HEAD = struct.Struct('<iII')      # header.stamp sec, nanosec, frame_id length
# bytes after the last field that rosbags' deserializer lets pass (alignment padding)
TRAILING = 3
HEADER_TYPE = 'std_msgs/msg/Header'
# struct codes of the fixed-size base types, by their names in rclpy's message classes
# (get_fields_and_field_types)
RCLPY_CODES = {'double': 'd', 'float': 'f', 'int8': 'b', 'uint8': 'B', 'octet': 'B',
               'char': 'B', 'int16': 'h', 'uint16': 'H', 'int32': 'i', 'uint32': 'I',
               'int64': 'q', 'uint64': 'Q'}


def offsets(codes: str, start: int) -> list[int]:
    """Return where each of `codes` lies, laid out from body offset `start` (CDR alignment)."""
    out, pos = [], start
    for code in codes:
        size = struct.calcsize(code)
        pos += -pos % size
        out.append(pos - start)
        pos += size
    return out


def tail(codes: str, start: int) -> struct.Struct:
    """Return the Struct of `codes` laid out from body offset `start` (CDR alignment)."""
    fmt, pos = '<', 0
    for code, at in zip(codes, offsets(codes, start)):
        fmt += 'x' * (at - pos) + code
        pos = at + struct.calcsize(code)
    return struct.Struct(fmt)


def rclpy_layout(cls: type) -> tuple[bool, list]:
    """
    Return (stamped, [(field, struct code)]) of an rclpy message class of fixed layout.

    As tskf_ros.bag.cdr.fixed_fields for rosbags' definition of the type, for a type
    whose fields are a std_msgs/Header (first, optional) and base types; raises ValueError
    for any other field (a nested type, a string, a sequence, an array, a bool).
    """
    fields = list(cls.get_fields_and_field_types().items())
    stamped = bool(fields) and fields[0][1] == 'std_msgs/Header'
    layout = []
    for name, kind in fields[1:] if stamped else fields:
        if kind not in RCLPY_CODES:
            raise ValueError(f'{cls.__name__}: field {name} ({kind}) has no fixed layout')
        layout.append((name, RCLPY_CODES[kind]))
    return stamped, layout


def layout_decoder(stamped: bool, layout: Sequence[tuple[str, str]],
                   fields: Sequence[str]) -> Callable[[Any], Optional[tuple]]:
    """
    Return decode(data) -> (stamp ns or None, *the values of `fields`), or None.

    The values rosbags' deserialize_cdr gives for the same bytes, read from the little-endian
    layout directly.  None where rosbags is left to decide (its values or its error): another
    encapsulation (big endian), bytes too short for the layout or with more than the 3
    trailing bytes rosbags allows, a frame_id without its NUL or not UTF-8.  stamp:
    header.stamp as sec * 1e9 + nanosec (None for a type without a header).
    """
    names = [name for name, _ in layout]
    picks = [names.index(f) for f in fields]
    codes = ''.join(code for _, code in layout)
    if len(picks) == 1:
        first = picks[0]

        def pick(values: tuple) -> tuple:
            return (values[first],)
    else:
        pick = operator.itemgetter(*picks)
    if not stamped:
        body = tail(codes, 0)
        need = 4 + body.size

        def decode_plain(data: Any) -> Optional[tuple]:
            if not need <= len(data) <= need + TRAILING or data[0] != 0 or data[1] != 1:
                return None
            return (None, *pick(body.unpack_from(data, 4)))
        return decode_plain
    # after the frame_id's bytes (body offset 12 + length): one Struct per offset mod 8
    tails = [tail(codes, k) for k in range(8)]
    head = STAMP_HEAD.unpack_from

    def decode(data: Any) -> Optional[tuple]:
        size = len(data)
        if size < 16 or data[0] != 0 or data[1] != 1:
            return None
        sec, nanosec, length = head(data, 4)
        end = 16 + length
        rest = tails[(end - 4) & 7]
        if not length or not end + rest.size <= size <= end + rest.size + TRAILING \
                or data[end - 1]:
            return None
        try:
            bytes(data[16:end - 1]).decode()
        except UnicodeDecodeError:
            return None
        return (sec * NS + nanosec, *pick(rest.unpack_from(data, end)))
    return decode
