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

"""Canonical CDR (XCDR1, rosbags' encoding) of what the package writes; fixed-layout codecs."""

import array
import struct
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray
from rosbags.interfaces import Nodetype

from tskf_ros.bag.message_types import typestore
from tskf_ros.core.units import NS
# the estimates' fixed-layout encoder is the live node's as well (messages layer)
from tskf_ros.messages.estimate_cdr import EstimateEncoder
from tskf_ros.messages.fixed_cdr import (HEADER_TYPE, layout_decoder, offsets as _offsets,
                                         tail as _tail, TRAILING as _TRAILING)

__all__ = ['EstimateEncoder', 'fixed_block_decoder', 'fixed_decoder', 'fixed_fields',
           'serialize', 'to_store', 'type_name']

_NUMPY = {'d': np.float64, 'f': np.float32, 'b': np.int8, 'B': np.uint8, 'h': np.int16,
          'H': np.uint16, 'i': np.int32, 'I': np.uint32, 'l': np.int64, 'L': np.uint64,
          'q': np.int64, 'Q': np.uint64}


def type_name(msg: Any) -> str:
    """Return 'package/msg/Name' of an rclpy message instance."""
    cls = type(msg)
    pkg, sub = cls.__module__.split('.')[:2]
    return f'{pkg}/{sub}/{cls.__name__}'


_CLASSES: dict = {}      # rclpy class -> (typestore class, field names)


def _store_class(msg: Any) -> tuple:
    cls = type(msg)
    entry = _CLASSES.get(cls)
    if entry is None:
        entry = _CLASSES[cls] = (typestore().types[type_name(msg)],
                                 tuple(msg.get_fields_and_field_types()))
    return entry


def _convert(value: Any) -> Any:
    if hasattr(value, 'get_fields_and_field_types'):
        return to_store(value)
    if isinstance(value, array.array):
        return np.array(value, dtype=_NUMPY[value.typecode])
    if isinstance(value, bytes) and len(value) == 1:     # a `byte` field
        return value[0]
    if isinstance(value, list):
        if value and isinstance(value[0], bytes):        # byte[]: a list of 1-byte bytes
            return np.frombuffer(b''.join(value), dtype=np.uint8)
        return [_convert(v) for v in value]
    return value


def to_store(msg: Any) -> Any:
    """Copy an rclpy message into the rosbags typestore's class of the same type."""
    cls, names = _store_class(msg)
    return cls(**{name: _convert(getattr(msg, name)) for name in names})


def serialize(msg: Any) -> bytes:
    """Return the canonical CDR bytes of an rclpy message (rosbags' serializer)."""
    return bytes(typestore().serialize_cdr(to_store(msg), type_name(msg)))


# struct codes of the fixed-size base types a fixed-layout decoder reads
_BASE_CODES = {'float64': 'd', 'float32': 'f', 'int8': 'b', 'uint8': 'B', 'byte': 'B',
               'char': 'B', 'int16': 'h', 'uint16': 'H', 'int32': 'i', 'uint32': 'I',
               'int64': 'q', 'uint64': 'Q'}


def fixed_fields(msgtype: str) -> tuple[bool, list]:
    """
    Return (stamped, [(field path, struct code)]) of a type of fixed layout.

    stamped: the type starts with a std_msgs/Header (the only variable-length part
    allowed); the fields are the rest, flattened ('accel.linear.x').  Raises ValueError
    for a type with another string, a sequence, an array or a bool.
    """
    fields = typestore().fielddefs[msgtype][1]
    stamped = bool(fields) and fields[0][1] == (Nodetype.NAME, HEADER_TYPE)
    out: list = []

    def walk(prefix: str, defs: list) -> None:
        for name, (node, spec) in defs:
            if node == Nodetype.NAME and spec != HEADER_TYPE:
                walk(f'{prefix}{name}.', typestore().fielddefs[spec][1])
            elif node == Nodetype.BASE and spec[0] in _BASE_CODES:
                out.append((prefix + name, _BASE_CODES[spec[0]]))
            else:
                raise ValueError(f'{msgtype}: field {prefix}{name} has no fixed layout')
    walk('', fields[1:] if stamped else fields)
    return stamped, out


def fixed_decoder(msgtype: str, fields: Sequence[str]) -> Callable[[Any], Optional[tuple]]:
    """
    Return decode(data) -> (stamp ns or None, *the values of `fields`), or None.

    fixed_cdr.layout_decoder of the type's layout in rosbags' definitions (fixed_fields):
    the values rosbags' deserialize_cdr gives for the same bytes, or None where rosbags is
    left to decide.
    """
    return layout_decoder(*fixed_fields(msgtype), fields)


def _column(rows: NDArray[np.uint8], at: int, code: str) -> NDArray[Any]:
    """Return the little-endian `code` values at byte `at` of every row."""
    size = struct.calcsize(code)
    return np.ascontiguousarray(rows[:, at:at + size]).view('<' + code)[:, 0]


def _cdr_header(rows: NDArray[np.uint8]) -> bool:
    """Whether every row starts with the little-endian CDR encapsulation (0, 1)."""
    return bool((rows[:, 0] == 0).all() and (rows[:, 1] == 1).all())


def fixed_block_decoder(msgtype: str, fields: Sequence[str]
                        ) -> Callable[[NDArray[np.uint8]], Optional[tuple]]:
    """
    Return decode(rows) -> (stamps ns or None, *the columns of `fields`), or None.

    rows: messages of one length, one per row (uint8).  Row for row what fixed_decoder
    gives (stamps int64, the values in their own types), read with numpy; None unless
    fixed_decoder gives a value for every row from one layout: one frame_id, the same in
    every row (the caller then decodes the rows one by one).
    """
    stamped, layout = fixed_fields(msgtype)
    names = [name for name, _ in layout]
    picks = [names.index(f) for f in fields]
    codes = ''.join(code for _, code in layout)
    wanted = [codes[p] for p in picks]
    if not stamped:
        at = _offsets(codes, 0)
        need = 4 + _tail(codes, 0).size

        def decode_plain(rows: NDArray[np.uint8]) -> Optional[tuple]:
            if not need <= rows.shape[1] <= need + _TRAILING or not _cdr_header(rows):
                return None
            return (None, *(_column(rows, 4 + at[p], c) for p, c in zip(picks, wanted)))
        return decode_plain
    sizes = [_tail(codes, k).size for k in range(8)]
    places = [_offsets(codes, k) for k in range(8)]

    def decode(rows: NDArray[np.uint8]) -> Optional[tuple]:
        size = rows.shape[1]
        if size < 16 or not _cdr_header(rows):
            return None
        lengths = _column(rows, 12, 'I')
        length = int(lengths[0])
        end = 16 + length
        k = (end - 4) & 7
        if (not length or not end + sizes[k] <= size <= end + sizes[k] + _TRAILING
                or not (lengths == length).all() or rows[:, end - 1].any()):
            return None
        frame = rows[0, 16:end - 1]
        if not (rows[:, 16:end - 1] == frame).all():
            return None
        try:
            frame.tobytes().decode()
        except UnicodeDecodeError:
            return None
        stamps = _column(rows, 4, 'i').astype(np.int64) * NS + _column(rows, 8, 'I')
        return (stamps, *(_column(rows, end + places[k][p], c)
                          for p, c in zip(picks, wanted)))
    return decode
