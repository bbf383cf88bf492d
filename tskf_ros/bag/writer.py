"""
Write rosbag2 MCAP bags with rosbags, atomically: a bag is either whole or not there.

The bag is written into a hidden temporary directory next to the target
(`.<name>.partial-XXXX/<name>`) and renamed to the target only when it is closed
properly, so an interrupted writer never leaves a half-written bag under the final name.
"""

import os
from pathlib import Path
import shutil
import tempfile
from typing import Optional, Sequence, Union

from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError

from tskf_ros.bag.message_types import BagTypeError, typestore
from tskf_ros.bag.reader import BagError

__all__ = ['BagExistsError', 'BagWriter', 'BagWriteError']

PathLike = Union[str, os.PathLike]


class BagExistsError(BagError):
    """The output bag exists and overwriting was not asked for."""


class BagWriteError(BagError):
    """The bag could not be written (type without a definition, I/O error)."""


class BagWriter:
    """
    A rosbag2 bag being written (MCAP storage, metadata version 9); use as a context manager.

    `add_topic` once per topic, then `write(topic, log_time_ns, cdr_bytes)`.  Leaving the
    `with` block normally renames the finished bag into place; leaving it with an exception
    deletes it.  `compress` zstd-compresses the MCAP chunks (rosbag2's storage compression).
    """

    def __init__(self, path: PathLike, *, overwrite: bool = False, compress: bool = False,
                 storage: str = 'mcap') -> None:
        self.path = Path(path)
        self.overwrite = overwrite
        self.compress = compress
        self.storage = storage
        self._tmp: Optional[Path] = None
        self._writer: Optional[Writer] = None
        self._conns: dict[str, Connection] = {}
        self.counts: dict[str, int] = {}

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

    def open(self) -> None:  # noqa: A003 (the file-like verb, as rosbags' Writer.open)
        """Check the target and open the temporary bag; raise BagExistsError if it exists."""
        if self.path.exists() and not self.overwrite:
            raise BagExistsError(f'{self.path}: exists already, not overwriting '
                                 '(use --overwrite)')
        parent = self.path.parent
        parent.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.partial-', dir=parent))
        plugin = StoragePlugin.MCAP if self.storage == 'mcap' else StoragePlugin.SQLITE3
        self._writer = Writer(self._tmp / self.path.name, version=9, storage_plugin=plugin)
        if self.compress:
            self._writer.set_compression(CompressionMode.STORAGE if self.storage == 'mcap'
                                         else CompressionMode.FILE, CompressionFormat.ZSTD)
        self._writer.open()

    @property
    def partial_path(self) -> Optional[Path]:
        """Where the bag is being written until it is closed."""
        return None if self._tmp is None else self._tmp / self.path.name

    def has_topic(self, topic: str) -> bool:
        """Say whether the topic was added."""
        return topic in self._conns

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[Qos] = (),
                  msgdef: Optional[str] = None) -> None:
        """
        Add a topic; its definition comes from the Jazzy typestore, else from `msgdef`.

        Raises BagTypeError if the type is neither in the typestore nor given a definition.
        """
        store = typestore()
        kwargs: dict = {'offered_qos_profiles': list(qos)}
        if msgtype in store.fielddefs:
            kwargs['typestore'] = store
        elif msgdef:
            kwargs['msgdef'] = msgdef
            kwargs['rihs01'] = 'RIHS01_' + '0' * 64     # unknown: rosbag2 accepts it
        else:
            raise BagTypeError(f'{msgtype} (topic {topic}) has no known definition')
        self._conns[topic] = self._writer.add_connection(topic, msgtype, **kwargs)
        self.counts[topic] = 0

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Write one serialized message with its log time."""
        self._writer.write(self._conns[topic], int(log_time_ns), data)
        self.counts[topic] += 1

    def close(self) -> Path:
        """Write metadata.yaml and the MCAP summary, then move the bag into place."""
        if self._writer is None:
            return self.path
        try:
            self._writer.close()
        except (WriterError, OSError) as exc:
            self.abort()
            raise BagWriteError(f'{self.path}: could not finish the bag: {exc}') from None
        self._writer = None
        if self.path.exists():
            if self.path.is_dir():
                shutil.rmtree(self.path)
            else:
                self.path.unlink()
        os.replace(self._tmp / self.path.name, self.path)
        shutil.rmtree(self._tmp, ignore_errors=True)
        self._tmp = None
        return self.path

    def abort(self) -> None:
        """Delete the partial bag (nothing is left under the final name)."""
        if self._writer is not None:
            try:
                self._writer.close()
            except (WriterError, OSError):
                pass
            self._writer = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
