"""
Write rosbag2 MCAP bags, atomically and with CRCs: a bag is whole, sealed, or not there.

MCAP files are written through the `mcap` package's Writer (chunk CRCs, the data-section
CRC in DataEnd, the summary CRC), with the rosbag2 `ros2` profile, one schema per type,
the offered QoS and type hash in each channel's metadata, and metadata.yaml (version 9)
written at the end as rosbag2 does; sqlite3 bags (storage='sqlite3') go through rosbags'
writer.  Every bag carries METADATA_MARKER in metadata.yaml's custom_data: `overwrite`
replaces only an empty directory or a bag with that marker and nothing but its files.

The bag is written into a hidden temporary directory next to the target
(`.<name>.partial-XXXX/<name>`) and renamed to the target only when it is closed, so an
interrupted writer never leaves a half-written bag under the final name.  `flush()` ends
the chunk in progress and fsyncs the file, so that a crash (SIGKILL, power loss) loses at
most what came after the last flush; `reindex` (tskf_ros.bag.reindex) turns such a
.partial directory into a bag.  A failed file write (ENOSPC: the disk filled) does not
lose what is already on disk: `close()` cuts the file after its last whole record, seals
it (DataEnd, Footer, magic: a valid MCAP file without a summary, which the `mcap` package
and rosbags both read), writes metadata.yaml from what is in the file and moves the bag
into place; `error` then says what happened.

Messages go into the chunk through `_ChunkWriter`, the mcap Writer with a faster
add_message (one struct.pack per message record, the message indexes kept as flat lists,
the statistics summed when the file is finished): the file it writes is the same, byte for
byte, as the mcap Writer's (test/test_bag_writer_fast.py), at a fraction of the cost
(bench/bench_offline.py).  It relies on the mcap Writer's private chunk builder and
statistics, of the pinned mcap version.
"""

import errno
import os
from pathlib import Path
import shutil
import struct
import tempfile
from typing import Optional, Sequence, Union

from mcap._chunk_builder import ChunkBuilder
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import Channel, DataEnd, Footer, Message, MessageIndex, Schema
from mcap.writer import CompressionType, Writer as McapWriter
from rosbags.interfaces import Qos
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.metadata import dump_qos_v9

from tskf_ros.bag.message_types import BagTypeError, typestore
from tskf_ros.bag.reader import BagError, BagFormatError, BagReader, MCAP_MAGIC, TopicInfo

import yaml

__all__ = ['BagExistsError', 'BagWriter', 'BagWriteError', 'DiskFullError', 'METADATA_MARKER',
           'scan_mcap', 'seal_mcap', 'write_metadata']

PathLike = Union[str, os.PathLike]
# custom_data key (and value) of every bag this package writes; overwrite needs it
METADATA_MARKER = ('tskf_ros.writer', 'tskf_ros')
# bytes of uncompressed records per chunk before the chunk is written (rosbag2: 768 KiB)
CHUNK_SIZE = 768 * 1024
# metadata.yaml version (rosbag2 Jazzy)
METADATA_VERSION = 9
NO_HASH = 'RIHS01_' + '0' * 64


# a Message record up to its data: opcode, length, channel, sequence, log and publish time
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')
_MESSAGE_FIXED = 22                 # the record's bytes before its data


class _FlatIndex(MessageIndex):
    """A MessageIndex whose records are a flat list [time, offset, time, offset, ...]."""

    def write(self, stream: RecordBuilder) -> None:
        flat = self.records
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(flat) * 8)
        stream.write(struct.pack(f'<{len(flat)}Q', *flat))
        stream.finish_record()


class _ChunkRecords(ChunkBuilder):
    """The mcap ChunkBuilder's records in a bytearray (_ChunkWriter.add_message adds them)."""

    def __init__(self) -> None:
        super().__init__()
        self.buf = bytearray()

    @property
    def count(self) -> int:
        return len(self.buf)

    def end(self) -> bytes:
        out = bytes(self.buf)
        self.buf.clear()
        return out

    def _record(self, record: object) -> None:
        builder = RecordBuilder()
        record.write(builder)
        self.buf += builder.end()

    def add_channel(self, channel: Channel) -> None:
        self._record(channel)

    def add_schema(self, schema: Schema) -> None:
        self._record(schema)

    def add_message(self, message: Message) -> None:
        raise NotImplementedError('messages go in through _ChunkWriter.add_message')

    def reset(self) -> None:
        super().reset()
        self.buf.clear()


class _ChunkWriter(McapWriter):
    """The mcap Writer (chunked), with the cheaper add_message of _ChunkRecords."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._chunk = self._Writer__chunk_builder = _ChunkRecords()
        self._limit = self._Writer__chunk_size
        self._finalize = self._Writer__finalize_chunk
        self._channel_counts: dict = {}       # in the order of their first message
        self._first: Optional[int] = None
        self._last = 0

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        """Add a message to the chunk in progress (as the mcap Writer's add_message)."""
        chunk = self._chunk      # the hot path of replay_offline: one pack per message
        buf = chunk.buf
        index = chunk.message_indices.get(channel_id)
        if index is None:
            index = chunk.message_indices[channel_id] = _FlatIndex(channel_id, [])
        index.records += (log_time, len(buf))
        buf += _MESSAGE_HEAD.pack(Opcode.MESSAGE, _MESSAGE_FIXED + len(data), channel_id,
                                  sequence, log_time, publish_time)
        buf += data
        if chunk.num_messages == 0:
            chunk.message_start_time = log_time
        elif log_time < chunk.message_start_time:
            chunk.message_start_time = log_time
        if log_time > chunk.message_end_time:
            chunk.message_end_time = log_time
        chunk.num_messages += 1
        counts = self._channel_counts
        counts[channel_id] = counts.get(channel_id, 0) + 1
        if self._first is None or log_time < self._first:
            self._first = log_time
        if log_time > self._last:
            self._last = log_time
        if len(buf) > self._limit:
            self._finalize()

    def finish(self) -> None:
        """Sum the statistics of the messages added, then finish as the mcap Writer."""
        stats = self._Writer__statistics
        for channel, count in self._channel_counts.items():
            stats.channel_message_counts[channel] += count
            stats.message_count += count
        if self._first is not None:
            stats.message_start_time = self._first
            stats.message_end_time = self._last
        super().finish()


class BagExistsError(BagError):
    """The output bag exists and overwriting was not asked for, or is not safe."""


class BagWriteError(BagError):
    """The bag could not be written (type without a definition, I/O error)."""


class DiskFullError(BagWriteError):
    """A write failed with ENOSPC; what was on disk before is kept (see BagWriter.close)."""


class _File:
    """An unbuffered output file that knows where its last whole write ended."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.pos = 0
        self.good = 0       # end of the last write() that reached the disk whole

    def _write_some(self, view: memoryview) -> int:
        """Write what the OS takes of view; return the count (tests inject faults here)."""
        return os.write(self.fd, view)

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view.nbytes:
            n = self._write_some(view)
            self.pos += n
            view = view[n:]
        self.good = self.pos
        return len(data)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass

    def sync(self) -> None:
        os.fsync(self.fd)

    def truncate(self, size: int) -> None:
        os.ftruncate(self.fd, size)
        self.pos = self.good = size
        os.lseek(self.fd, size, os.SEEK_SET)

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).splitlines()
    return text[0] if text else type(exc).__name__


def seal_mcap(path: Path) -> tuple[int, bool]:
    """
    Close an MCAP file that was never finished: cut it after its last whole record, end it.

    Walks the top-level records (headers only); the file is truncated after the last record
    that is wholly in it (before a DataEnd or Footer, if any) and DataEnd, a Footer without
    summary and the magic are appended.  Returns (bytes kept of the original, whether bytes
    were cut).  Raises BagError if it is not an MCAP file, OSError if it cannot be written.
    """
    size = path.stat().st_size
    with path.open('rb') as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise BagFormatError(f'{path}: not an MCAP file (bad magic bytes)')
        end = pos = len(MCAP_MAGIC)
        while True:
            head = f.read(9)
            if len(head) < 9:
                break
            opcode, length = head[0], int.from_bytes(head[1:], 'little')
            if opcode in (0x0F, 0x02) or opcode == 0 or pos + 9 + length > size:
                break           # DataEnd, Footer, garbage or a record cut short
            pos += 9 + length
            end = pos
            f.seek(pos)
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    with path.open('r+b') as f:
        f.truncate(end)
        f.seek(end)
        f.write(builder.end() + MCAP_MAGIC)
        f.flush()
        os.fsync(f.fileno())
    return end, end != size


def scan_mcap(path: Path) -> tuple:
    """
    Read an MCAP file's messages (up to any damage) for its metadata.

    Returns (topics {name: (TopicInfo, type hash)}, counts {name: n}, first, last log time,
    damage or None).
    """
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
    return topics, counts, lo, hi, reader.damage


def write_metadata(bagdir: Path, path: Path, *, stats: Optional[tuple] = None,
                   custom_data: Optional[dict] = None) -> dict:
    """
    Write bagdir/metadata.yaml (rosbag2 version 9) for the MCAP file `path`; return it.

    stats: what scan_mcap returns (topics, counts, first, last); read from the file if None.
    """
    topics, counts, lo, hi = (stats or scan_mcap(path))[:4]
    total = sum(counts.values())
    per_file = [{'path': path.name,
                 'starting_time': {'nanoseconds_since_epoch': lo or 0},
                 'duration': {'nanoseconds': (hi - lo) if total else 0},
                 'message_count': total}]
    storage, compression = 'mcap', ''
    data = dict(custom_data or {})
    data[METADATA_MARKER[0]] = METADATA_MARKER[1]
    info = {
        'version': METADATA_VERSION,
        'storage_identifier': storage,
        'relative_file_paths': [path.name],
        'duration': {'nanoseconds': (hi - lo) if total else 0},
        'starting_time': {'nanoseconds_since_epoch': lo or 0},
        'message_count': total,
        'topics_with_message_count': [
            {'topic_metadata': {'name': name, 'type': ti.msgtype,
                                'serialization_format': ti.serialization_format or 'cdr',
                                'offered_qos_profiles': dump_qos_v9(ti.qos),
                                'type_description_hash': digest},
             'message_count': counts.get(name, 0)}
            for name, (ti, digest) in topics.items()],
        'compression_format': compression,
        'compression_mode': '',
        'files': per_file,
        'custom_data': data,
        'ros_distro': 'jazzy',
    }
    doc = {'rosbag2_bagfile_information': info}
    tmp = bagdir / '.metadata.yaml.tmp'
    with tmp.open('w') as f:
        yaml.safe_dump(doc, f, default_flow_style=False, sort_keys=False)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(bagdir / 'metadata.yaml')
    return info


def check_replaceable(path: Path) -> None:
    """
    Raise BagExistsError unless `path` may be replaced by a new bag.

    Only an empty directory, or a bag directory this package wrote (METADATA_MARKER in its
    custom_data) holding nothing but metadata.yaml and the storage files it names, is.
    """
    refuse = f'{path}: exists and is not a bag written by tskf_ros'
    if path.is_symlink() or not path.is_dir():
        raise BagExistsError(f'{path}: exists and is not a directory; not overwriting')
    entries = {p.name: p for p in path.iterdir()}
    if not entries:
        return
    try:
        doc = yaml.safe_load((path / 'metadata.yaml').read_text())
        info = doc['rosbag2_bagfile_information']
        names = {str(n) for n in info['relative_file_paths']}
        marked = (info.get('custom_data') or {}).get(METADATA_MARKER[0]) == METADATA_MARKER[1]
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError):
        raise BagExistsError(f'{refuse} (no readable metadata.yaml); not overwriting') \
            from None
    if not marked:
        raise BagExistsError(f'{refuse} (no {METADATA_MARKER[0]} in its custom_data); '
                             'not overwriting')
    extra = sorted(set(entries) - names - {'metadata.yaml'})
    if extra or any('/' in n or n in ('.', '..') for n in names):
        raise BagExistsError(f'{refuse} alone (it also holds {", ".join(extra) or "paths"}); '
                             'not overwriting')
    for name in names:
        p = entries.get(name)
        if p is not None and (p.is_symlink() or not p.is_file()
                              or p.suffix not in ('.mcap', '.db3', '.zstd')):
            raise BagExistsError(f'{refuse}: {name} is not a storage file; not overwriting')


class BagWriter:
    """
    A rosbag2 bag being written (MCAP storage, metadata version 9); use as a context manager.

    `add_topic` once per topic, then `write(topic, log_time_ns, cdr_bytes)`.  Leaving the
    `with` block normally renames the finished bag into place; leaving it with an exception
    deletes it.  `compress` zstd-compresses the MCAP chunks (rosbag2's storage compression).
    After a failed write (`error` set, DiskFullError on ENOSPC) `write` raises the error
    again; `close` keeps and seals what reached the disk.
    """

    def __init__(self, path: PathLike, *, overwrite: bool = False, compress: bool = False,
                 storage: str = 'mcap', chunk_size: int = CHUNK_SIZE) -> None:
        self.path = Path(path)
        self.overwrite = overwrite
        self.compress = compress
        self.storage = storage
        self.chunk_size = chunk_size
        self._tmp: Optional[Path] = None
        self._writer: Optional[Writer] = None         # sqlite3 (rosbags)
        self._mcap: Optional[McapWriter] = None
        self._file: Optional[_File] = None
        self._conns: dict = {}
        self._schemas: dict[str, int] = {}
        self.custom_data: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self._topics: dict = {}
        self._lo: Optional[int] = None
        self._hi: Optional[int] = None
        self.error: Optional[BagWriteError] = None
        self.dropped = 0

    def __enter__(self) -> 'BagWriter':
        """Open the temporary bag."""
        self.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Finish (rename into place) on success, delete on an exception."""
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def check_target(self) -> None:
        """Raise a BagError if the output path cannot be used (before anything is made)."""
        name = self.path.name
        if not name or name in ('.', '..') or self.path.resolve() == Path('/'):
            raise BagWriteError(f'{self.path}: not a usable bag name (give a directory '
                                'name such as out/run1)')
        if self.path.exists() or self.path.is_symlink():
            if not self.overwrite:
                raise BagExistsError(f'{self.path}: exists already, not overwriting '
                                     '(use --overwrite)')
            check_replaceable(self.path)
        parent = self.path.parent
        while not parent.exists():
            parent = parent.parent
        if not parent.is_dir():
            raise BagWriteError(f'{self.path}: {parent} is not a directory')
        if not os.access(parent, os.W_OK | os.X_OK):
            raise BagWriteError(f'{self.path}: cannot write in {parent} (permission denied)')

    def open(self) -> None:  # noqa: A003 (the file-like verb, as rosbags' Writer.open)
        """Check the target and open the temporary bag; raise BagExistsError if it exists."""
        self.check_target()
        parent = self.path.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.partial-',
                                              dir=parent))
            bagdir = self._tmp / self.path.name
            if self.storage == 'sqlite3':
                self._writer = Writer(bagdir, version=METADATA_VERSION,
                                      storage_plugin=StoragePlugin.SQLITE3)
                if self.compress:
                    self._writer.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
                self._writer.open()
                return
            bagdir.mkdir()
            self._file = _File(bagdir / f'{self.path.name}.mcap')
            self._mcap = _ChunkWriter(
                self._file, chunk_size=self.chunk_size,
                compression=CompressionType.ZSTD if self.compress else CompressionType.NONE,
                enable_crcs=True, enable_data_crcs=True)
            self._mcap.start(profile='ros2', library='tskf_ros (mcap python writer)')
        except (OSError, WriterError) as exc:
            self.abort()
            raise BagWriteError(f'{self.path}: cannot create the bag: '
                                f'{_one_line(exc)}') from None

    @property
    def partial_path(self) -> Optional[Path]:
        """Where the bag is being written until it is closed."""
        return None if self._tmp is None else self._tmp / self.path.name

    def has_topic(self, topic: str) -> bool:
        """Say whether the topic was added."""
        return topic in self._conns

    def set_custom_data(self, key: str, value: str) -> None:
        """Set a custom_data entry of metadata.yaml."""
        self.custom_data[key] = str(value)

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[Qos] = (),
                  msgdef: Optional[str] = None) -> None:
        """
        Add a topic; its definition comes from the Jazzy typestore, else from `msgdef`.

        Raises BagTypeError if the type is neither in the typestore nor given a definition.
        """
        store = typestore()
        if msgtype in store.fielddefs:
            msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
            digest = store.hash_rihs01(msgtype)
        elif msgdef:
            digest = NO_HASH        # unknown: rosbag2 accepts it
        else:
            raise BagTypeError(f'{msgtype} (topic {topic}) has no known definition')
        if self._writer is not None:
            self._conns[topic] = self._writer.add_connection(
                topic, msgtype, msgdef=msgdef, rihs01=digest, offered_qos_profiles=list(qos))
            self.counts[topic] = 0
            return
        if msgtype not in self._schemas:
            encoding = 'ros2idl' if msgdef.startswith('=' * 80 + '\nIDL: ') else 'ros2msg'
            self._schemas[msgtype] = self._guard(
                self._mcap.register_schema, msgtype, encoding, msgdef.encode())
        qos_text = yaml.safe_dump(dump_qos_v9(list(qos)), default_flow_style=False).strip()
        self._conns[topic] = self._guard(
            self._mcap.register_channel, topic, 'cdr', self._schemas[msgtype],
            {'offered_qos_profiles': qos_text if qos else '', 'topic_type_hash': digest})
        self._topics[topic] = (TopicInfo(topic, msgtype, qos=list(qos)), digest)
        self.counts[topic] = 0

    def _guard(self, call, *args):
        """Run a write of the mcap writer; turn an OSError into BagWriteError (kept)."""
        if self.error is not None:
            raise self.error
        try:
            return call(*args)
        except OSError as exc:
            raise self._failed(exc) from None

    def _failed(self, exc: OSError) -> BagWriteError:
        """Keep and return the BagWriteError (DiskFullError on ENOSPC) of a failed write."""
        cls = DiskFullError if exc.errno == errno.ENOSPC else BagWriteError
        what = 'the disk is full' if cls is DiskFullError else 'write failed'
        self.error = cls(f'{self.path}: {what} ({_one_line(exc)}) after '
                         f'{self._file.good if self._file else 0} bytes')
        return self.error

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Write one serialized message with its log time (raises BagWriteError if failed)."""
        count = self.counts[topic]
        t = int(log_time_ns)
        if self._writer is not None:
            self._writer.write(self._conns[topic], t, data)
            self.counts[topic] = count + 1
            return
        if self.error is not None:
            self.dropped += 1
            raise self.error
        try:         # the hot path of replay_offline: _guard inlined
            self._mcap.add_message(self._conns[topic], t, data, t, count & 0xFFFFFFFF)
        except OSError as exc:
            raise self._failed(exc) from None
        self.counts[topic] = count + 1
        if self._lo is None:
            self._lo = self._hi = t
        elif t < self._lo:
            self._lo = t
        elif t > self._hi:
            self._hi = t

    def flush(self) -> None:
        """End the chunk in progress and make everything written so far durable (fsync)."""
        if self._mcap is not None and self.error is None:
            self._guard(self._mcap.flush)
            self._guard(self._file.sync)

    def close(self) -> Path:
        """
        Finish the bag (summary, metadata.yaml) and move it into place; return its path.

        After a write error the file is sealed as it is on disk (see the module doc) and
        moved into place all the same; `error` says what happened.  Raises BagWriteError
        (the partial bag is then kept for `reindex`) if even that fails.
        """
        if self._tmp is None:
            return self.path
        bagdir = self._tmp / self.path.name
        try:
            if self._writer is not None:
                self._writer.close()
                self._writer = None
                self._finish_metadata(bagdir)
            else:
                if self.error is None:
                    try:
                        self._guard(self._mcap.finish)
                        self._file.sync()
                    except BagWriteError:
                        pass
                if self.error is not None:
                    self._file.truncate(self._file.good)
                self._file.close()
                self._mcap = None
                stats = (self._topics, self.counts, self._lo, self._hi)
                if self.error is not None:
                    seal_mcap(self._file.path)
                    self.custom_data['tskf_ros.incomplete'] = str(self.error)
                    stats = scan_mcap(self._file.path)
                    self.counts = {n: stats[1].get(n, 0) for n in self.counts}
                write_metadata(bagdir, self._file.path, stats=stats,
                               custom_data=self.custom_data)
            self._move_into_place(bagdir)
        except (WriterError, OSError, BagError) as exc:
            keep = self._tmp
            if self._file is not None:
                self._file.close()
            self._tmp = None
            raise BagWriteError(f'{self.path}: could not finish the bag ({_one_line(exc)}); '
                                f'what was written is in {keep} (run reindex on it)') from None
        return self.path

    def _finish_metadata(self, bagdir: Path) -> None:
        """Add the marker and custom data to the metadata.yaml rosbags wrote."""
        meta = bagdir / 'metadata.yaml'
        doc = yaml.safe_load(meta.read_text())
        info = doc['rosbag2_bagfile_information']
        data = dict(info.get('custom_data') or {})
        data.update(self.custom_data)
        data[METADATA_MARKER[0]] = METADATA_MARKER[1]
        info['custom_data'] = data
        tmp = bagdir / '.metadata.yaml.tmp'
        tmp.write_text(yaml.safe_dump(doc, default_flow_style=False, sort_keys=False))
        tmp.replace(meta)

    def _move_into_place(self, bagdir: Path) -> None:
        old = None
        if self.path.exists() or self.path.is_symlink():
            check_replaceable(self.path)
            old = self._tmp / '.replaced'
            os.replace(self.path, old)
        os.replace(bagdir, self.path)
        shutil.rmtree(self._tmp, ignore_errors=True)
        self._tmp = None

    def abort(self) -> None:
        """Delete the partial bag (nothing is left under the final name)."""
        if self._writer is not None:
            try:
                self._writer.close()
            except (WriterError, OSError):
                pass
            self._writer = None
        if self._file is not None:
            self._file.close()
        self._mcap = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
