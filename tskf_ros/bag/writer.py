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

"""Write a rosbag2 bag (MCAP `ros2` profile, or sqlite3), whole or not at all: rosbag2 Jazzy."""

import errno
import os
from pathlib import Path
import shutil
import tempfile
from typing import Callable, Optional, Sequence, TypeVar, Union

from mcap.writer import CompressionType, Writer as McapWriter
from rosbags.interfaces import Qos
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.metadata import dump_qos_v9

from tskf_ros.bag.bag_metadata import (add_custom_data, METADATA_MARKER, METADATA_VERSION,
                                       write_metadata)
from tskf_ros.bag.mcap_file import McapStats, NO_HASH, OutputFile, scan_mcap, seal_mcap
from tskf_ros.bag.message_types import BagTypeError, typestore
from tskf_ros.bag.partials import remove_stale, work_dir
from tskf_ros.bag.reader import BagError, resolved, TopicInfo

import yaml

__all__ = ['BagExistsError', 'BagWriter', 'BagWriteError', 'check_replaceable', 'CHUNK_SIZE',
           'DiskFullError']

PathLike = Union[str, os.PathLike]
T = TypeVar('T')
# bytes of uncompressed records per chunk before the chunk is written (rosbag2: 768 KiB)
CHUNK_SIZE = 768 * 1024
# what the MCAP Header record names as its writer
LIBRARY = 'tskf_ros (mcap python writer)'


class BagExistsError(BagError):
    """The output bag exists and overwriting was not asked for, or is not safe."""


class BagWriteError(BagError):
    """The bag could not be written (type without a definition, I/O error)."""


class DiskFullError(BagWriteError):
    """A write failed with ENOSPC; what was on disk before is kept (see BagWriter.close)."""


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).splitlines()
    return text[0] if text else type(exc).__name__


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
    again; `close` keeps and seals what reached the disk (doc/design/bags.md).
    disposable: an output that can be made again (replay_offline's): its hidden directory
    names the process (partials.work_dir), and `open` deletes those of processes gone.
    """

    def __init__(self, path: PathLike, *, overwrite: bool = False, compress: bool = False,
                 storage: str = 'mcap', chunk_size: int = CHUNK_SIZE,
                 disposable: bool = False) -> None:
        self.path = Path(path)
        self.disposable = disposable
        self.overwrite = overwrite
        self.compress = compress
        self.storage = storage
        self.chunk_size = chunk_size
        self._tmp: Optional[Path] = None
        self._writer: Optional[Writer] = None         # sqlite3 (rosbags)
        self._mcap: Optional[McapWriter] = None
        self._file: Optional[OutputFile] = None
        self._conns: dict = {}
        self._schemas: dict[str, int] = {}
        self.custom_data: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self._topics: dict = {}
        self._lo: Optional[int] = None
        self._hi: Optional[int] = None
        self.error: Optional[BagWriteError] = None

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
        if not name or name in ('.', '..') or resolved(self.path) == Path('/'):
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
            if self.disposable:
                remove_stale(self.path)
                self._tmp = work_dir(self.path)
            else:
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
            self._file = OutputFile(bagdir / f'{self.path.name}.mcap')
            self._mcap = McapWriter(
                self._file, chunk_size=self.chunk_size,
                compression=CompressionType.ZSTD if self.compress else CompressionType.NONE,
                enable_crcs=True, enable_data_crcs=True)
            self._mcap.start(profile='ros2', library=LIBRARY)
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

    def _guard(self, call: Callable[..., T], *args) -> T:
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
        self.write_many(log_time_ns, ((topic, data),))

    def write_many(self, log_time_ns: int, messages: Sequence[tuple[str, bytes]]) -> None:
        """Write serialized messages (topic, bytes), all with one log time, in order."""
        t = int(log_time_ns)
        counts = self.counts
        if self._writer is not None:
            for topic, data in messages:
                self._writer.write(self._conns[topic], t, data)
                counts[topic] += 1
            return
        if self.error is not None:
            raise self.error
        add, conns = self._mcap.add_message, self._conns
        try:         # the hot path of replay_offline
            for topic, data in messages:
                count = counts[topic]
                add(conns[topic], t, data, t, count & 0xFFFFFFFF)
                counts[topic] = count + 1
        except OSError as exc:
            raise self._failed(exc) from None
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

        After a write error the file is cut after its last whole write and sealed (DataEnd,
        Footer, magic) and moved into place all the same; `error` says what happened.
        Raises BagWriteError (the partial bag is then kept for `reindex`) if even that fails.
        """
        if self._tmp is None:
            return self.path
        bagdir = self._tmp / self.path.name
        try:
            if self._writer is not None:
                self._writer.close()
                self._writer = None
                add_custom_data(bagdir, self.custom_data)
            else:
                self._finish_mcap(bagdir)
            self._move_into_place(bagdir)
        except (WriterError, OSError, BagError) as exc:
            keep = self._tmp
            if self._file is not None:
                self._file.close()
            self._tmp = None
            raise BagWriteError(f'{self.path}: could not finish the bag ({_one_line(exc)}); '
                                f'what was written is in {keep} (run reindex on it)') from None
        return self.path

    def _finish_mcap(self, bagdir: Path) -> None:
        """Write the summary (or seal what is on disk after a failed write), metadata.yaml."""
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
        stats = McapStats(self._topics, self.counts, self._lo, self._hi)
        if self.error is not None:
            seal_mcap(self._file.path)
            self.custom_data['tskf_ros.incomplete'] = str(self.error)
            stats = scan_mcap(self._file.path)
            self.counts = {n: stats.counts.get(n, 0) for n in self.counts}
        write_metadata(bagdir, self._file.path, stats=stats, custom_data=self.custom_data)

    def _move_into_place(self, bagdir: Path) -> None:
        if self.path.exists() or self.path.is_symlink():
            check_replaceable(self.path)
            os.replace(self.path, self._tmp / '.replaced')
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
