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

"""An MCAP file on disk: the writer's output stream, sealing an unfinished file, scanning one."""

import os
from pathlib import Path
from typing import NamedTuple, Optional
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import DataEnd, Footer

from tskf_ros.bag.reader import BagFormatError, BagReader, Damage, MCAP_MAGIC

__all__ = ['McapStats', 'NO_HASH', 'OutputFile', 'scan_mcap', 'seal_mcap']

# type_description_hash of a type without a known definition (rosbag2 accepts it)
NO_HASH = 'RIHS01_' + '0' * 64
# bytes of a record's opcode and length
_RECORD_HEAD = 9
# bytes read at a time for the data section's CRC
_CRC_BLOCK = 1 << 20


class McapStats(NamedTuple):
    """What metadata.yaml says of an MCAP file: topics, counts, first and last log time."""

    topics: dict        # name -> (TopicInfo, type hash)
    counts: dict        # name -> messages
    first: Optional[int]
    last: Optional[int]
    damage: Optional[Damage] = None


class OutputFile:
    """An unbuffered output file that knows where its last whole write ended."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.pos = 0
        self.good = 0       # end of the last write() that reached the disk whole

    def write_some(self, view: memoryview) -> int:
        """Write what the OS takes of view; return the count (tests inject faults here)."""
        return os.write(self.fd, view)

    def write(self, data: bytes) -> int:
        """Write all of data (the mcap Writer's stream interface)."""
        view = memoryview(data)
        while view.nbytes:
            n = self.write_some(view)
            self.pos += n
            view = view[n:]
        self.good = self.pos
        return len(data)

    def tell(self) -> int:
        """Return the position (the mcap Writer's stream interface)."""
        return self.pos

    def flush(self) -> None:
        """Do nothing: every write goes to the OS at once (the mcap Writer calls it)."""

    def sync(self) -> None:
        """Make everything written durable (fsync)."""
        os.fsync(self.fd)

    def truncate(self, size: int) -> None:
        """Cut the file to `size` bytes and write on from there."""
        os.ftruncate(self.fd, size)
        self.pos = self.good = size
        os.lseek(self.fd, size, os.SEEK_SET)

    def close(self) -> None:
        """Close the file (again: nothing)."""
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def seal_mcap(path: Path) -> tuple[int, bool]:
    """
    Close an MCAP file that was never finished: cut it after its last whole record, end it.

    Walks the top-level records (headers only); the file is truncated after the last record
    that is wholly in it (before a DataEnd or Footer, if any) and DataEnd, a Footer without
    summary and the magic are appended; DataEnd carries the data section's CRC-32 (as the
    mcap Writer with data CRCs computes it).  Returns (bytes kept of the original, whether bytes
    were cut).  Raises BagError if it is not an MCAP file, OSError if it cannot be written.
    """
    size = path.stat().st_size
    with path.open('rb') as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagFormatError(f'{path}: not an MCAP file (bad magic bytes)')
        end = pos = len(MCAP_MAGIC)
        while True:
            head = f.read(_RECORD_HEAD)
            if len(head) < _RECORD_HEAD:
                break
            opcode, length = head[0], int.from_bytes(head[1:], 'little')
            if (opcode in (Opcode.DATA_END, Opcode.FOOTER) or opcode == 0
                    or pos + _RECORD_HEAD + length > size):
                break           # DataEnd, Footer, garbage or a record cut short
            pos += _RECORD_HEAD + length
            end = pos
            f.seek(pos)
    with path.open('r+b') as f:
        f.truncate(end)
        crc = 0         # the data section's CRC-32: every byte before DataEnd, magic included
        while f.tell() < end:
            crc = zlib.crc32(f.read(min(_CRC_BLOCK, end - f.tell())), crc)
        builder = RecordBuilder()
        DataEnd(data_section_crc=crc).write(builder)
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
        f.seek(end)
        f.write(builder.end() + MCAP_MAGIC)
        f.flush()
        os.fsync(f.fileno())
    return end, end != size


def scan_mcap(path: Path) -> McapStats:
    """Read an MCAP file's messages (up to any damage) for its metadata."""
    reader = BagReader(path)
    counts: dict = {}
    lo = hi = None
    for msg in reader.messages():
        counts[msg.topic] = counts.get(msg.topic, 0) + 1
        t = msg.log_time_ns
        lo = t if lo is None else min(lo, t)
        hi = t if hi is None else max(hi, t)
    topics = {name: (info, reader.type_hashes.get(name, NO_HASH))
              for name, info in reader.topics.items()}
    return McapStats(topics, counts, lo, hi, reader.damage)
