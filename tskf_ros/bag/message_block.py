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

"""A chunk's messages read at once: where they all have one length, one numpy view of the chunk."""

from dataclasses import dataclass
from typing import Iterator, NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

__all__ = ['MessageBlock', 'RawMessage', 'uniform_blocks']

# bytes of a Message record's framing and fixed fields (MCAP spec, "Message"): opcode u8,
# record length u64, channel id u16, sequence u32, log time u64, publish time u64
_FRAMING = 9
_FIELDS = 22
_MESSAGE = 0x05
_INT64_MAX = np.iinfo(np.int64).max


class RawMessage(NamedTuple):
    """One serialized message: topic, type, log (receive) time in ns, CDR bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


@dataclass
class MessageBlock:
    """
    Consecutive messages of one topic in storage order, their payloads of one length.

    log_times: int64 log (receive) times in ns; payloads: rows x payload length, uint8 (a
    view of the decompressed chunk).  messages() gives them one by one, as RawMessage.
    """

    topic: str
    msgtype: str
    log_times: NDArray[np.int64]
    payloads: NDArray[np.uint8]

    def __len__(self) -> int:
        """Return the number of messages."""
        return len(self.log_times)

    def messages(self) -> Iterator[RawMessage]:
        """Yield the messages one by one, as the per-message walk of the chunk yields them."""
        topic, msgtype = self.topic, self.msgtype
        for log_ns, row in zip(self.log_times.tolist(), self.payloads):
            yield RawMessage(topic, msgtype, log_ns, row.tobytes())


def _record_dtype(length: int) -> np.dtype:
    """Return the numpy layout of a Message record of `length` bytes after its framing."""
    return np.dtype([('opcode', 'u1'), ('length', '<u8'), ('channel', '<u2'),
                     ('sequence', '<u4'), ('log_time', '<u8'), ('publish_time', '<u8'),
                     ('data', 'u1', (length - _FIELDS,))])


def uniform_blocks(data: bytes, start: int, end: int, channels: dict,
                   wanted: Optional[set]) -> Optional[list[MessageBlock]]:
    """
    Return the Message records of data[start:end] as blocks, or None where they do not fit.

    They fit where every record from `start` to `end` is a Message of one record length,
    on a known channel (channels: id -> (topic, type)), with log times below 2**63 and
    at most one change of channel in 16 messages; then the blocks are the runs of one
    channel (those of `wanted` topics, if given), in order.  Otherwise None: the caller
    walks the records one by one (and meets any problem there, in order).
    """
    if end - start < _FRAMING + _FIELDS + 1 or data[start] != _MESSAGE:
        return None
    length = int.from_bytes(data[start + 1:start + _FRAMING], 'little')
    stride = _FRAMING + length
    if length <= _FIELDS or (end - start) % stride:
        return None
    count = (end - start) // stride
    records = np.frombuffer(data, dtype=_record_dtype(length), count=count, offset=start)
    if not ((records['opcode'] == _MESSAGE).all() and (records['length'] == length).all()):
        return None
    logs = records['log_time']
    if logs.max() > _INT64_MAX:
        return None
    ids = records['channel']
    cuts = np.flatnonzero(ids[1:] != ids[:-1]) + 1
    if len(cuts) > count // 16:
        return None
    bounds = [0, *cuts.tolist(), count]
    blocks = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        channel = channels.get(int(ids[a]))
        if channel is None:
            return None
        if wanted is None or channel[0] in wanted:
            blocks.append(MessageBlock(channel[0], channel[1], logs[a:b].astype(np.int64),
                                       records['data'][a:b]))
    return blocks
