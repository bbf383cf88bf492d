"""
Read rosbag2 bags (MCAP or sqlite3 storage) message by message, surviving damage.

A bag is a directory with metadata.yaml and its storage files, as `ros2 bag record` writes,
or a bare .mcap file.  MCAP files are read sequentially record by record (the mcap
package's record parsers, not its summary-based reader), so that a file truncated in the
middle of a chunk or with a corrupt chunk still yields every message before the damage;
the damage is then kept in `BagReader.damage` and the iteration stops.  sqlite3 bags
(older rosbag2) are read with rosbags' reader.

Problems that make a bag unreadable raise a BagError subclass whose message is one line
naming the file and the problem.
"""

from dataclasses import dataclass, field
from io import BytesIO
import os
from pathlib import Path
import struct
import sys
from typing import Iterable, Iterator, NamedTuple, Optional, Union
import zlib

import lz4.frame
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import read_magic
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.rosbag2 import Reader as Sqlite3Reader
from rosbags.rosbag2.errors import ReaderError
import yaml
import zstandard

__all__ = ['BagEmptyError', 'BagError', 'BagFormatError', 'BagNotFoundError', 'BagReader',
           'Damage', 'MetadataError', 'RawMessage', 'TopicInfo']

PathLike = Union[str, os.PathLike]
MCAP_MAGIC = b'\x89MCAP0\r\n'
# exit status of a command whose input bag was damaged (what it could read was used)
EXIT_DAMAGED = 3
# what the record parsers raise on bytes that are not a valid MCAP record sequence
# (lz4 raises RuntimeError on a bad frame)
DAMAGE_ERRORS = (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError,
                 zstandard.ZstdError, MemoryError, OverflowError, RuntimeError, KeyError,
                 TypeError, IndexError)


def error_exit(prog: str, exc: Exception, path: object = '') -> int:
    """Print a command's error in one line (an OSError names its file) and return 1."""
    if isinstance(exc, OSError):
        print(f'{prog}: error: {exc.filename or path}: {exc.strerror or exc}', file=sys.stderr)
    else:
        print(f'{prog}: error: {exc}', file=sys.stderr)
    return 1


def exit_status(prog: str, damage: Optional['Damage'], what: str) -> int:
    """Return 0, or print the damage in one line (prefixed by prog and what) and EXIT_DAMAGED."""
    if damage is None:
        return 0
    print(f'{prog}: {what}: {damage}', file=sys.stderr)
    return EXIT_DAMAGED


def _int_or_none(value: object) -> Optional[int]:
    return None if value is None else int(value)


class BagError(Exception):
    """A bag that cannot be read; str() is one line naming the file and the problem."""


class BagNotFoundError(BagError):
    """The bag, or a file its metadata lists, does not exist."""


class BagEmptyError(BagError):
    """A storage file of zero bytes, or a bag without messages."""


class MetadataError(BagError):
    """metadata.yaml is missing or unreadable."""


class BagFormatError(BagError):
    """Not an MCAP or sqlite3 rosbag2 file, or a storage this reader does not know."""


class RawMessage(NamedTuple):
    """One serialized message: topic, type, log (receive) time in ns, CDR bytes."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


@dataclass
class TopicInfo:
    """A topic of a bag: type, message count (if known), offered QoS, definition."""

    name: str
    msgtype: str
    count: Optional[int] = None
    qos: list = field(default_factory=list)
    msgdef: Optional[str] = None
    serialization_format: str = 'cdr'


@dataclass(frozen=True)
class Damage:
    """Where reading stopped: the file, the byte offset, the problem, messages before."""

    path: str
    offset: int
    problem: str
    messages_before: int

    def __str__(self) -> str:
        """One line: file, problem, offset and what was read before."""
        return (f'{self.path}: {self.problem} at byte {self.offset}; the '
                f'{self.messages_before} message(s) before it were read')


def _qos_time(d: object) -> QosTime:
    if isinstance(d, dict):
        return QosTime(int(d.get('sec', 0)), int(d.get('nsec', 0)))
    return QosTime(0, 0)


def parse_qos(value: object) -> list:
    """Parse offered_qos_profiles of metadata v4-v9 (a list, or a YAML string of one)."""
    if isinstance(value, str):
        try:
            value = yaml.safe_load(value) if value.strip() else []
        except yaml.YAMLError:
            return []
    out = []
    for item in value or []:
        if not isinstance(item, dict):
            continue

        def enum(cls, key, default):
            raw = item.get(key, default)
            try:
                return cls(raw) if isinstance(raw, int) else cls[str(raw).upper()]
            except (KeyError, ValueError):
                return cls[default.upper()] if isinstance(default, str) else cls(default)
        out.append(Qos(
            history=enum(QosHistory, 'history', 'keep_last'), depth=int(item.get('depth', 0)),
            reliability=enum(QosReliability, 'reliability', 'reliable'),
            durability=enum(QosDurability, 'durability', 'volatile'),
            deadline=_qos_time(item.get('deadline')), lifespan=_qos_time(item.get('lifespan')),
            liveliness=enum(QosLiveliness, 'liveliness', 'automatic'),
            liveliness_lease_duration=_qos_time(item.get('liveliness_lease_duration')),
            avoid_ros_namespace_conventions=bool(item.get('avoid_ros_namespace_conventions',
                                                          False))))
    return out


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
        self.duration_ns: Optional[int] = None
        if not self.path.exists():
            raise BagNotFoundError(f'{self.path}: no such bag (file or directory)')
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
            self.duration_ns = _int_or_none((info.get('duration') or {}).get('nanoseconds'))
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
        top = self.path.resolve()
        for name, f in zip(names, self.files):
            # confined: a name such as ../../x or /etc/x would read outside the bag
            if not f.resolve().is_relative_to(top) or f.resolve() == top:
                raise MetadataError(f'{meta}: storage file {name!r} is outside the bag '
                                    'directory; not reading it')
        for f in self.files:
            if not f.is_file():
                raise BagNotFoundError(f'{f}: listed in metadata.yaml but missing')
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
        self.damage = None
        wanted = set(topics) if topics is not None else None
        if self.storage == 'sqlite3':
            yield from self._sqlite3(wanted)
            return
        count = 0
        for path in self.files:
            for msg in self._mcap(path, wanted, count):
                count += 1
                yield msg
            if self.damage is not None:
                return

    def _sqlite3(self, wanted: Optional[set]) -> Iterator[RawMessage]:
        count = 0
        try:
            with Sqlite3Reader(self.path) as reader:
                conns = [c for c in reader.connections
                         if wanted is None or c.topic in wanted]
                for c in reader.connections:
                    info = self.topics.setdefault(c.topic, TopicInfo(c.topic, c.msgtype))
                    info.msgdef = c.msgdef.data
                for conn, stamp, data in reader.messages(connections=conns):
                    count += 1
                    yield RawMessage(conn.topic, conn.msgtype, int(stamp), bytes(data))
        except (ReaderError, OSError) as exc:
            if count == 0:
                raise BagFormatError(f'{self.files[0]}: {exc}') from None
            self.damage = Damage(str(self.files[0]), -1, str(exc), count)

    def _mcap(self, path: Path, wanted: Optional[set], before: int) -> Iterator[RawMessage]:
        """Yield the messages of one MCAP file, record by record, up to DataEnd or damage."""
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
                        for msg in self._chunk(chunk, schemas, channels, wanted, path,
                                               offset):
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
                        msg = self._message(m, channels, wanted)
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
    def _message(m: Message, channels: dict, wanted: Optional[set]) -> Optional[RawMessage]:
        ch = channels.get(m.channel_id)
        if ch is None:
            raise ValueError(f'message on unknown channel {m.channel_id}')
        if wanted is not None and ch[0] not in wanted:
            return None
        return RawMessage(ch[0], ch[1], m.log_time, m.data)

    def _chunk(self, chunk: Chunk, schemas: dict, channels: dict, wanted: Optional[set],
               path: Path, offset: int) -> Iterator[RawMessage]:
        """Yield the messages of a chunk; a record that does not fit it is damage."""
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
