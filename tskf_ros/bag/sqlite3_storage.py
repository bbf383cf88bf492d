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

"""The messages of a rosbag2 sqlite3 bag, file by file, through rosbags' .db3 storage reader."""

from contextlib import ExitStack
from pathlib import Path
import shutil
import tempfile
from typing import Callable, Iterator, NamedTuple, Optional

from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader, ReaderError
import zstandard

__all__ = ['compression_mode', 'Sqlite3Message', 'sqlite3_messages', 'StorageFileError']


class StorageFileError(Exception):
    """A .db3 file that cannot be read (further): `path` and the problem in one line."""

    def __init__(self, path: Path, problem: str) -> None:
        super().__init__(f'{path}: {problem}')
        self.path = path
        self.problem = problem


class Sqlite3Message(NamedTuple):
    """One stored message: its storage file, the file's connection, log time, bytes."""

    path: Path
    connection: Connection
    log_time_ns: int
    data: bytes


def compression_mode(metadata: dict) -> str:
    """Return metadata.yaml's compression mode: '' (none), 'file' or 'message'."""
    mode = str(metadata.get('compression_mode') or '').lower()
    return '' if mode == 'none' else mode


def _storage_file(path: Path, mode: str, stack: ExitStack) -> Path:
    """Return a .db3 file to open: the file itself, or its zstd-decompressed copy."""
    if mode != 'file':
        return path
    tmp = Path(stack.enter_context(tempfile.TemporaryDirectory()))
    plain = tmp / (path.stem if path.suffix == '.zstd' else path.name)
    if plain.suffix != '.db3':
        plain = plain.with_name(plain.name + '.db3')
    with path.open('rb') as src, zstandard.ZstdDecompressor().stream_reader(src) as inp, \
            plain.open('wb') as out:
        shutil.copyfileobj(inp, out)
    return plain


def sqlite3_messages(files: list[Path], mode: str, wanted: Optional[set] = None,
                     seen: Optional[Callable[[list[Connection]], None]] = None
                     ) -> Iterator[Sqlite3Message]:
    """
    Yield the messages of a bag's .db3 files, each file in log time order, files in order.

    Each file is opened alone, with the topics of its own `topics` table: rosbags'
    directory reader pairs metadata.yaml's topics with the storage's by their whole offered
    QoS string, and rosbag2 writes the two differently (deadline 0/0 in the metadata,
    2147483647/4294967295 in the storage), which would read such a bag as empty.
    `mode` is compression_mode(): a 'file' is decompressed first, a 'message' each message;
    `seen` is called with each file's connections before its messages.
    Raises StorageFileError on what it cannot read.
    """
    unpack = zstandard.ZstdDecompressor().decompress if mode == 'message' else None
    for path in files:
        try:
            yield from _file_messages(path, mode, wanted, seen, unpack)
        except (ReaderError, OSError, zstandard.ZstdError) as exc:
            text = str(exc).splitlines()
            if isinstance(exc, OSError) and exc.strerror:
                text = [exc.strerror]
            raise StorageFileError(path, text[0] if text else type(exc).__name__) from None


def _file_messages(path: Path, mode: str, wanted: Optional[set],
                   seen: Optional[Callable[[list[Connection]], None]],
                   unpack: Optional[Callable[[bytes], bytes]]) -> Iterator[Sqlite3Message]:
    """Yield the messages of one .db3 file (see sqlite3_messages)."""
    with ExitStack() as stack:
        reader = stack.enter_context(Reader(_storage_file(path, mode, stack)))
        if seen is not None:
            seen(list(reader.connections))
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not conns:
            return              # (no connections would mean every one to rosbags)
        for conn, stamp, data in reader.messages(connections=conns):
            yield Sqlite3Message(path, conn, int(stamp),
                                 unpack(data) if unpack is not None else bytes(data))
