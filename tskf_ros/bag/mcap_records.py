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

"""An MCAP file's data section record by record: framing walked here, records read by mcap."""

from io import BytesIO
import struct
from typing import BinaryIO, Iterator
import zlib

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, InvalidMagic, RecordLengthLimitExceeded
from mcap.opcode import Opcode
from mcap.records import (Attachment, Channel, Chunk, DataEnd, Footer, Header, McapRecord,
                          Message, Metadata, Schema)
from mcap.stream_reader import CRCValidationError

__all__ = ['DataRecords', 'MCAP_MAGIC']

MCAP_MAGIC = b'\x89MCAP0\r\n'
_RECORD_HEAD = struct.Struct('<BQ')         # opcode, length
# the records of a data section read through the package's record classes; others
# (MessageIndex above all: one per channel and chunk, entry by entry through read8) are
# skipped unparsed, as a sequential read does not need them
_PARSED = {int(Opcode.HEADER): Header.read, int(Opcode.SCHEMA): Schema.read,
           int(Opcode.CHANNEL): Channel.read, int(Opcode.CHUNK): Chunk.read,
           int(Opcode.ATTACHMENT): Attachment.read, int(Opcode.METADATA): Metadata.read,
           int(Opcode.FOOTER): Footer.read}
_MESSAGE, _DATA_END = int(Opcode.MESSAGE), int(Opcode.DATA_END)


class DataRecords:
    """
    The records of an MCAP file from its magic to DataEnd (or a Footer), in order.

    Iterating yields what `mcap.stream_reader.StreamReader(f, emit_chunks=True,
    validate_crcs=True, record_size_limit=size).records` yields up to there, with the same
    errors (InvalidMagic, EndOfFile, RecordLengthLimitExceeded, CRCValidationError of the
    data section), but MessageIndex records (and other index records) are skipped
    unparsed.  `start`: the byte offset of the record yielded or being read (the damage's
    offset if reading it raises).
    """

    def __init__(self, f: BinaryIO, size: int) -> None:
        self.f, self.size = f, size
        self.start = len(MCAP_MAGIC)

    def __iter__(self) -> Iterator[McapRecord]:
        """Read the records one at a time: each whole before it is parsed."""
        f, size = self.f, self.size
        magic = f.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            raise InvalidMagic(tuple(magic))
        crc = zlib.crc32(magic)     # the data section's CRC: every byte before DataEnd
        self.start = len(MCAP_MAGIC)
        while True:
            head = f.read(_RECORD_HEAD.size)
            if len(head) < _RECORD_HEAD.size:
                raise EndOfFile()
            opcode, length = _RECORD_HEAD.unpack(head)
            if length > size:
                raise RecordLengthLimitExceeded(opcode, length, size)
            body = f.read(length)
            if len(body) < length:
                raise EndOfFile()
            if opcode == _DATA_END:
                end = DataEnd.read(ReadDataStream(BytesIO(body)))
                if end.data_section_crc not in (0, crc):
                    raise CRCValidationError(expected=end.data_section_crc, actual=crc,
                                             record=end)
                yield end
                return
            crc = zlib.crc32(body, zlib.crc32(head, crc))
            if opcode == _MESSAGE:
                yield Message.read(ReadDataStream(BytesIO(body)), length)
            else:
                parse = _PARSED.get(opcode)
                if parse is not None:
                    yield parse(ReadDataStream(BytesIO(body)))
                    if opcode == Opcode.FOOTER:
                        return
            self.start += _RECORD_HEAD.size + length
