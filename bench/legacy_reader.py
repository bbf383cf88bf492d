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
Two other MCAP readers, for bench/bench_offline.py only: the measured alternatives.

- LegacyReader: the package's reader before it read through the mcap package (its own
  record walk, zstd/lz4 decompression and CRC checks), kept verbatim in its MCAP part.
- LibraryOnlyReader: the package's reader with the mcap package's breakup_chunk walking
  the records inside a chunk too (the reader's _chunk says why it does not).

Both reuse the package's BagReader for everything else (metadata, channels, damage).
"""

from io import BytesIO
from pathlib import Path
import struct
from typing import Iterator, Optional
import zlib

import lz4.frame
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk, read_magic
from tskf_ros.bag.reader import BagReader, Damage, DAMAGE_ERRORS, RawMessage
import zstandard


class LibraryOnlyReader(BagReader):
    """The package's reader, with the mcap package's breakup_chunk inside chunks."""

    def _chunk(self, chunk: Chunk, schemas: dict, channels: dict,
               wanted: Optional[set]) -> Iterator[RawMessage]:
        for record in breakup_chunk(chunk, validate_crc=True):
            if isinstance(record, Message):
                msg = self._message(record.channel_id, record.log_time, record.data,
                                    channels, wanted)
                if msg is not None:
                    yield msg
            elif isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = self._channel(record, schemas)


class LegacyReader(BagReader):
    """The package's reader before this revision (MCAP part verbatim, renamed methods)."""

    def _mcap(self, path: Path, wanted: Optional[set], before: int) -> Iterator[RawMessage]:
        schemas: dict[int, Schema] = {}
        channels: dict[int, tuple] = {}
        count = 0
        offset = 0
        where = 'a record'
        size = path.stat().st_size
        with path.open('rb') as f:
            stream = ReadDataStream(f, calculate_crc=True)
            try:
                read_magic(stream)
                while True:
                    offset = stream.count
                    crc = stream.checksum()
                    where = 'a record'
                    opcode = stream.read1()
                    length = stream.read8()
                    start = stream.count
                    if start + length > size:
                        where = 'a chunk' if opcode == Opcode.CHUNK else 'a record'
                        raise EndOfFile()
                    if opcode == Opcode.CHUNK:
                        where = 'a chunk'
                        chunk = Chunk.read(stream)
                        for msg in self._legacy_chunk(chunk, schemas, channels, wanted):
                            count += 1
                            yield msg
                    elif opcode == Opcode.SCHEMA:
                        s = Schema.read(stream)
                        schemas[s.id] = s
                    elif opcode == Opcode.CHANNEL:
                        c = Channel.read(stream)
                        channels[c.id] = self._channel(c, schemas)
                    elif opcode == Opcode.MESSAGE:
                        m = Message.read(stream, length)
                        msg = self._message(m.channel_id, m.log_time, m.data, channels, wanted)
                        if msg is not None:
                            count += 1
                            yield msg
                    elif opcode == Opcode.DATA_END:
                        expected = stream.read4() if length >= 4 else 0
                        if expected and expected != crc:
                            where = 'the data section'
                            raise ValueError('data section CRC mismatch: the file was '
                                             'changed after it was written')
                        return
                    elif opcode == Opcode.FOOTER:
                        return
                    else:
                        stream.read(length)
                    padding = length - (stream.count - start)
                    if padding < 0:
                        raise ValueError(f'record overruns its length by {-padding} bytes')
                    if padding:
                        stream.read(padding)
            except (EOFError, EndOfFile):
                self.damage = Damage(str(path), offset, f'truncated in {where}',
                                     before + count)
            except DAMAGE_ERRORS as exc:
                text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                self.damage = Damage(str(path), offset, f'corrupt {where} ({text})',
                                     before + count)

    def _legacy_chunk(self, chunk: Chunk, schemas: dict, channels: dict,
                      wanted: Optional[set]) -> Iterator[RawMessage]:
        if chunk.compression == 'zstd':
            data = zstandard.ZstdDecompressor().decompress(
                chunk.data, max_output_size=chunk.uncompressed_size)
        elif chunk.compression == 'lz4':
            data = lz4.frame.decompress(chunk.data)
        elif chunk.compression == '':
            data = chunk.data
        else:
            raise ValueError(f'unsupported chunk compression {chunk.compression!r}')
        if len(data) != chunk.uncompressed_size:
            raise ValueError(f'chunk holds {len(data)} bytes, its header says '
                             f'{chunk.uncompressed_size}')
        if chunk.uncompressed_crc:
            if zlib.crc32(data) != chunk.uncompressed_crc:
                raise ValueError('chunk CRC mismatch')
        view = memoryview(data)
        pos, end = 0, len(data)
        lo, hi = chunk.message_start_time, chunk.message_end_time
        while pos < end:
            if end - pos < 9:
                raise ValueError('chunk ends inside a record header')
            opcode = view[pos]
            (length,) = struct.unpack_from('<Q', view, pos + 1)
            body = pos + 9
            if length > end - body:
                raise ValueError(f'record of {length} bytes overruns its chunk')
            if opcode == Opcode.MESSAGE:
                if length < 22:
                    raise ValueError('message record too short')
                cid, _, log_time = struct.unpack_from('<HIQ', view, body)
                ch = channels.get(cid)
                if ch is None:
                    raise ValueError(f'message on unknown channel {cid}')
                if not lo <= log_time <= hi:
                    raise ValueError(f'message time {log_time} outside the chunk range '
                                     f'[{lo}, {hi}]')
                if wanted is None or ch[0] in wanted:
                    yield RawMessage(ch[0], ch[1], log_time,
                                     bytes(view[body + 22:body + length]))
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                sub = ReadDataStream(BytesIO(bytes(view[body:body + length])))
                if opcode == Opcode.SCHEMA:
                    s = Schema.read(sub)
                    schemas[s.id] = s
                else:
                    c = Channel.read(sub)
                    channels[c.id] = self._channel(c, schemas)
            elif opcode == 0 or opcode > 0x0F:
                raise ValueError(f'unknown record opcode {opcode:#x} in a chunk')
            pos = body + length
