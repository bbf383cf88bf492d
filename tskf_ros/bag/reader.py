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

"""Read rosbag2 bags (MCAP, sqlite3) message by message, keeping what precedes any damage."""

from dataclasses import dataclass, field
from io import BytesIO
import os
from pathlib import Path
import struct
from typing import Iterable, Iterator, Optional, Union

from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError, RecordLengthLimitExceeded
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Schema
from mcap.stream_reader import CRCValidationError, get_chunk_data_stream
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import parse_qos as rosbags_parse_qos

from tskf_ros.bag.bag_errors import (BagEmptyError, BagError, BagFormatError,
                                     BagNotFoundError, check_exists, Damage, error_exit,
                                     EXIT_DAMAGED, exit_status, MetadataError, resolved)
from tskf_ros.bag.mcap_records import DataRecords, MCAP_MAGIC
from tskf_ros.bag.message_block import MessageBlock, RawMessage, uniform_blocks
from tskf_ros.bag.sqlite3_storage import compression_mode, sqlite3_messages, StorageFileError

import yaml
import zstandard

# the errors are bag_errors', here too for the modules that import them from the reader
__all__ = ['BagEmptyError', 'BagError', 'BagFormatError', 'BagNotFoundError', 'BagReader',
           'check_exists', 'Damage', 'error_exit', 'EXIT_DAMAGED', 'exit_status',
           'MessageBlock', 'MetadataError', 'RawMessage', 'resolved', 'TopicInfo']

PathLike = Union[str, os.PathLike]
# what the mcap package raises on bytes that are not a valid MCAP record sequence
# (CRCValidationError is a ValueError; lz4 raises RuntimeError on a bad frame)
DAMAGE_ERRORS = (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError,
                 zstandard.ZstdError, MemoryError, OverflowError, RuntimeError, KeyError,
                 TypeError, IndexError)
_RECORD_HEAD = struct.Struct('<BQ')         # opcode, length
_MESSAGE_HEAD = struct.Struct('<H4xQ')      # channel id, (sequence), log time
MESSAGE = int(Opcode.MESSAGE)


def _int_or_none(value: object) -> Optional[int]:
    return None if value is None else int(value)


@dataclass
class TopicInfo:
    """A topic of a bag: type, message count (if known), offered QoS, definition."""

    name: str
    msgtype: str
    count: Optional[int] = None
    qos: list = field(default_factory=list)
    msgdef: Optional[str] = None
    serialization_format: str = 'cdr'


def parse_qos(value: object) -> list:
    """
    Parse offered_qos_profiles of metadata v4-v9 (a list, or a YAML string of one).

    rosbags' parser; profiles it cannot read (a field missing) give [] (unknown QoS: the
    player then offers its default), not an error, as the rest of the bag is readable.
    """
    try:
        return rosbags_parse_qos(value)
    except (ReaderError, KeyError, TypeError, AttributeError, ValueError):
        return []


class BagReader:
    """
    A rosbag2 bag opened for reading: `topics`, `storage`, then `messages()` once or more.

    Raises a BagError subclass from the constructor if the bag cannot be opened at all.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = Path(path)
        self.topics: dict[str, TopicInfo] = {}
        self.type_hashes: dict[str, str] = {}
        self.damage: Optional[Damage] = None
        self.metadata: dict = {}
        self.message_count: Optional[int] = None
        self.start_ns: Optional[int] = None
        check_exists(self.path)
        if self.path.is_file():
            self._open_file()
        else:
            self._open_directory()

    # -- opening --------------------------------------------------------------------------

    def _open_file(self) -> None:
        if self.path.suffix == '.db3':
            raise MetadataError(f'{self.path}: an sqlite3 bag file is read through its '
                                'directory with metadata.yaml; give the directory')
        self._check_mcap(self.path)
        self.storage = 'mcap'
        self.files = [self.path]
        # no metadata: one pass finds the topics, their types and counts
        counts: dict = {}
        for msg in self.messages():
            counts[msg.topic] = counts.get(msg.topic, 0) + 1
        for name, info in self.topics.items():
            info.count = counts.get(name, 0)
        self.message_count = sum(counts.values())

    def _open_directory(self) -> None:
        meta = self.path / 'metadata.yaml'
        if not meta.is_file():
            hint = sorted(self.path.glob('*.mcap'))
            extra = f' (to read the MCAP file alone, give its path: {hint[0]})' if hint else ''
            raise MetadataError(f'{meta}: missing; not a rosbag2 bag directory{extra}')
        try:
            doc = yaml.safe_load(meta.read_text())
            info = doc['rosbag2_bagfile_information']
            self.storage = str(info['storage_identifier'])
            names = [str(p) for p in info['relative_file_paths']]
            self.metadata = info
            self.message_count = _int_or_none(info.get('message_count'))
            self.start_ns = _int_or_none(
                (info.get('starting_time') or {}).get('nanoseconds_since_epoch'))
            for entry in info.get('topics_with_message_count') or []:
                md = entry.get('topic_metadata', {})
                name = md.get('name')
                if name:
                    name = str(name)
                    self.topics[name] = TopicInfo(
                        name, str(md.get('type', '')),
                        _int_or_none(entry.get('message_count')),
                        parse_qos(md.get('offered_qos_profiles', [])),
                        serialization_format=str(md.get('serialization_format', 'cdr')))
                    if md.get('type_description_hash'):
                        self.type_hashes[name] = str(md['type_description_hash'])
        except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError,
                UnicodeDecodeError) as exc:
            raise MetadataError(f'{meta}: unreadable metadata ({type(exc).__name__}: '
                                f'{str(exc).splitlines()[0] if str(exc) else exc!r})') from None
        if self.storage not in ('mcap', 'sqlite3'):
            raise BagFormatError(f'{meta}: storage {self.storage!r} is not supported '
                                 '(mcap or sqlite3)')
        self.files = [self.path / n for n in names]
        if not self.files:
            raise BagEmptyError(f'{meta}: lists no storage files')
        top = resolved(self.path)
        for name, f in zip(names, self.files):
            # confined: a name such as ../../x or /etc/x would read outside the bag
            if not resolved(f).is_relative_to(top) or resolved(f) == top:
                raise MetadataError(f'{meta}: storage file {name!r} is outside the bag '
                                    'directory; not reading it')
        for f in self.files:
            check_exists(f, 'file, although metadata.yaml lists it')
            if not f.is_file():
                raise BagFormatError(f'{f}: listed in metadata.yaml but not a file')
            if self.storage == 'mcap':
                self._check_mcap(f)
            elif f.stat().st_size == 0:
                raise BagEmptyError(f'{f}: empty file (0 bytes)')

    @staticmethod
    def _check_mcap(path: Path) -> None:
        size = path.stat().st_size
        if size == 0:
            raise BagEmptyError(f'{path}: empty file (0 bytes)')
        with path.open('rb') as f:
            head = f.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise BagFormatError(f'{path}: not an MCAP file (bad magic bytes)')

    # -- reading --------------------------------------------------------------------------

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[RawMessage]:
        """
        Yield the messages in storage order (only those of `topics` if given).

        On damage, stop, and leave the description in `self.damage`.
        """
        for item in self.message_blocks(topics, blocks=False):
            yield item  # type: ignore[misc]  # blocks=False: RawMessage only

    def message_blocks(self, topics: Optional[Iterable[str]] = None, *, blocks: bool = True
                       ) -> Iterator[Union[RawMessage, MessageBlock]]:
        """
        Yield what messages() yields, with runs of a chunk's messages as MessageBlocks.

        A chunk whose messages (after its schemas and channels) all have one record length
        gives its runs of one topic as blocks (message_block.uniform_blocks: a numpy view
        of the chunk, no object per message); other messages come one by one.
        blocks=False: one by one only (messages()).
        """
        self.damage = None
        wanted = set(topics) if topics is not None else None
        count = 0
        if self.storage == 'sqlite3':
            for msg in self._sqlite3(wanted):
                count += 1
                yield msg
        else:
            for path in self.files:
                for msg in self._mcap(path, wanted, count, blocks):
                    count += 1 if msg.__class__ is RawMessage else len(msg)
                    yield msg
                if self.damage is not None:
                    return
        if count == 0 and wanted is None and self.damage is None and self.message_count:
            # never an empty bag where metadata.yaml lists messages
            self.damage = Damage(str(self.files[0]), -1, f'holds no message, although '
                                 f'metadata.yaml lists {self.message_count}', 0)

    def _sqlite3(self, wanted: Optional[set]) -> Iterator[RawMessage]:
        """Yield the messages of the .db3 files (sqlite3_storage: each file's own topics)."""
        count = 0

        def seen(connections: list) -> None:
            for c in connections:
                info = self.topics.setdefault(c.topic, TopicInfo(c.topic, c.msgtype))
                if c.msgdef.data and info.msgdef is None:
                    info.msgdef = c.msgdef.data
        try:
            for msg in sqlite3_messages(self.files, compression_mode(self.metadata),
                                        wanted, seen):
                count += 1
                yield RawMessage(msg.connection.topic, msg.connection.msgtype,
                                 msg.log_time_ns, msg.data)
        except StorageFileError as exc:
            if count == 0:
                raise BagFormatError(str(exc)) from None
            self.damage = Damage(str(exc.path), -1, exc.problem, count)

    def _mcap(self, path: Path, wanted: Optional[set], before: int,
              blocks: bool) -> Iterator[Union[RawMessage, MessageBlock]]:
        """
        Yield the messages of one MCAP file up to DataEnd, or up to the first damaged record.

        The records are walked by mcap_records.data_records (the mcap package's record
        classes; the data section's CRC) and the chunks decompressed and checked by the
        package's get_chunk_data_stream; at the first error the damage is kept in
        self.damage (doc/design/bags.md).
        """
        channels: dict[int, tuple] = {}
        schemas: dict[int, Schema] = {}
        count = 0
        size = path.stat().st_size
        with path.open('rb') as f:
            # a record longer than the file is truncation, not a reason to allocate it
            walk = DataRecords(f, size)
            try:
                for record in walk:
                    if isinstance(record, Chunk):
                        for item in self._chunk(record, schemas, channels, wanted, blocks):
                            count += 1 if item.__class__ is RawMessage else len(item)
                            yield item
                    elif isinstance(record, Message):
                        msg = self._message(record.channel_id, record.log_time, record.data,
                                            channels, wanted)
                        if msg is not None:
                            count += 1
                            yield msg
                    elif isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        channels[record.id] = self._channel(record, schemas)
                    elif isinstance(record, DataEnd):
                        break
                    elif isinstance(record, Footer):
                        return
            except DAMAGE_ERRORS as exc:
                offset = walk.start
                self.damage = Damage(str(path), offset, self._problem(exc, path, offset, size),
                                     before + count)
                return
            self._summary_channels(path, schemas)

    def _summary_channels(self, path: Path, schemas: dict) -> None:
        """
        Add the topics whose Channel is in the summary section only (a topic without messages).

        The mcap Writer writes no chunk without messages, so such a Channel is nowhere else.
        The summary is only an index: if it is damaged, the messages read stand.
        """
        try:
            with path.open('rb') as f:
                summary = make_reader(f).get_summary()
            if summary is None:
                return
            schemas = {**summary.schemas, **schemas}
            for channel in summary.channels.values():
                if channel.topic not in self.topics:
                    self._channel(channel, schemas)
        except Exception:  # noqa: B902 - the summary is an index: if it breaks, skip it
            pass

    @staticmethod
    def _problem(exc: Exception, path: Path, offset: int, size: int) -> str:
        """Describe in a few words the damage at `offset` that raised `exc`."""
        with path.open('rb') as f:
            f.seek(offset)
            where = 'a chunk' if f.read(1) == bytes([Opcode.CHUNK]) else 'a record'
        if isinstance(exc, CRCValidationError):
            if isinstance(exc.record, DataEnd):
                return ('corrupt the data section (data section CRC mismatch: the file was '
                        'changed after it was written)')
            return f'corrupt {where} (chunk CRC mismatch)'
        if isinstance(exc, (EOFError, EndOfFile)) or (
                isinstance(exc, RecordLengthLimitExceeded) and offset < size):
            return f'truncated in {where}'
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return f'corrupt {where} ({text})'

    def _channel(self, c: Channel, schemas: dict) -> tuple:
        schema = schemas.get(c.schema_id)
        msgtype = schema.name if schema is not None else ''
        info = self.topics.get(c.topic)
        digest = c.metadata.get('topic_type_hash')
        if digest:
            self.type_hashes.setdefault(c.topic, digest)
        if info is None:
            qos = parse_qos(c.metadata.get('offered_qos_profiles', ''))
            info = self.topics[c.topic] = TopicInfo(c.topic, msgtype, None, qos,
                                                    serialization_format=c.message_encoding)
        if schema is not None and info.msgdef is None:
            info.msgdef = schema.data.decode('utf-8', 'replace')
        return c.topic, msgtype or info.msgtype

    @staticmethod
    def _message(channel_id: int, log_time: int, data: bytes, channels: dict,
                 wanted: Optional[set]) -> Optional[RawMessage]:
        ch = channels.get(channel_id)
        if ch is None:
            raise ValueError(f'message on unknown channel {channel_id}')
        if wanted is not None and ch[0] not in wanted:
            return None
        return RawMessage(ch[0], ch[1], log_time, data)

    def _chunk(self, chunk: Chunk, schemas: dict, channels: dict, wanted: Optional[set],
               blocks: bool) -> Iterator[Union[RawMessage, MessageBlock]]:
        """
        Yield the messages of a chunk (decompressed and CRC-checked by the mcap package).

        The records inside are walked here (MCAP record framing: opcode, length), schemas
        and channels read by the package's record classes; a record that does not fit the
        chunk is damage.  blocks: from the first message on, try uniform_blocks once.
        """
        stream, end = get_chunk_data_stream(chunk, validate_crc=True)
        if end != chunk.uncompressed_size:
            raise ValueError(f'chunk holds {end} bytes, its header says '
                             f'{chunk.uncompressed_size}')
        data = stream.read(end)
        pos = 0
        record_head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
        while pos < end:
            if end - pos < 9:
                raise ValueError('chunk ends inside a record header')
            opcode, length = record_head(data, pos)
            body = pos + 9
            pos = body + length
            if pos > end:
                raise ValueError(f'record of {length} bytes overruns its chunk')
            if opcode == MESSAGE:
                if blocks:
                    blocks = False
                    got = uniform_blocks(data, body - 9, end, channels, wanted)
                    if got is not None:
                        yield from got
                        return
                if length < 22:
                    raise ValueError('message record too short')
                cid, log_time = message_head(data, body)
                ch = channels.get(cid)
                if ch is None:
                    raise ValueError(f'message on unknown channel {cid}')
                if wanted is None or ch[0] in wanted:
                    yield RawMessage(ch[0], ch[1], log_time, data[body + 22:pos])
            elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
                sub = ReadDataStream(BytesIO(data[body:pos]))
                if opcode == Opcode.SCHEMA:
                    s = Schema.read(sub)
                    schemas[s.id] = s
                else:
                    c = Channel.read(sub)
                    channels[c.id] = self._channel(c, schemas)
