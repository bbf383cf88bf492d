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
The estimates as canonical CDR (XCDR1, little endian), written directly in their fixed layout.

What the live node publishes (serialized, `Publisher.publish(bytes)`) and what a replay
writes to a bag: std_msgs/msg/Float64MultiArray in the layout of
conversions.state_estimate_to_msg, the bytes rosbags' serializer gives for that message
(tested bit for bit, NaNs included), without building the message.
"""

import struct
from typing import Sequence

import numpy as np

from tskf_ros.core.units import NS
from tskf_ros.messages.conversions import ESTIMATE_OFFSET

CDR_HEADER = b'\x00\x01\x00\x00'    # XCDR1, little endian, no options
_FLOAT64 = np.dtype(np.float64)


class _Layout:
    """CDR bytes being laid out: pos is the offset in the body (after the 4-byte header)."""

    def __init__(self, pos: int) -> None:
        self.data = bytearray()
        self.pos = pos

    def put(self, raw: bytes, align: int = 1) -> None:
        pad = -self.pos % align
        self.data += b'\0' * pad + raw
        self.pos += pad + len(raw)

    def string(self, text: str) -> None:
        raw = text.encode('utf-8') + b'\0'
        self.put(struct.pack('<I', len(raw)) + raw, 4)

    def cut(self, skip: int) -> bytes:
        """Return the bytes so far and start anew after `skip` bytes laid out elsewhere."""
        out = bytes(self.data)
        self.data = bytearray()
        self.pos += skip
        return out


class EstimateEncoder:
    """
    The estimator's outputs as canonical CDR, written directly in their fixed layout.

    Each is a std_msgs/msg/Float64MultiArray in the layout of
    conversions.state_estimate_to_msg.  One encoder per replay or node config: the state
    names are fixed, so the layout of each kind of estimate is laid out once; each message
    is then one struct.pack of its data.
    """

    KINDS = ('predicted', 'corrected', 'smoothed')

    def __init__(self, names: Sequence[str]) -> None:
        n = len(names)
        if not n:
            raise ValueError('an estimate needs at least one state')
        self.n = n
        count = ESTIMATE_OFFSET + n + n * n
        self._prefix = {}
        for kind in self.KINDS:
            lay = _Layout(0)
            lay.put(struct.pack('<I', 2), 4)
            lay.string(kind)
            lay.put(struct.pack('<II', n + 1, (n + 1) * n), 4)
            lay.string(','.join(names))
            lay.put(struct.pack('<II', n, n), 4)
            lay.put(struct.pack('<II', ESTIMATE_OFFSET, count), 4)
            lay.put(b'', 8)
            self._prefix[kind] = CDR_HEADER + lay.cut(0)
        self._data = struct.Struct(f'<{count}d')

    def estimate(self, kind: str, stamp_ns: int, mu: float, x: np.ndarray,
                 P: np.ndarray) -> bytes:
        """Return conversions.state_estimate_to_msg(kind, ...) serialized."""
        n = self.n
        sec, nsec = divmod(int(stamp_ns), NS)
        # the filter's own arrays as they are (numpy's float64 descriptor), else converted
        if x.__class__ is not np.ndarray or x.dtype is not _FLOAT64 or x.shape != (n,):
            x = np.asarray(x, dtype=float).reshape(n)
        P = (P.ravel() if P.__class__ is np.ndarray and P.dtype is _FLOAT64 and P.size == n * n
             else np.asarray(P, dtype=float).reshape(n * n))
        return self._prefix[kind] + self._data.pack(sec, nsec, mu, *x.tolist(), *P.tolist())
