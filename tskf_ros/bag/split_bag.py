"""A bag split into several MCAP files by size or duration, as `ros2 bag record -b/-d`."""

import os
from pathlib import Path
import shutil
import tempfile
from typing import Optional, Sequence, Union

from rosbags.interfaces import Qos

from tskf_ros.bag.bag_metadata import merge_metadata, write_yaml
from tskf_ros.bag.reader import BagError
from tskf_ros.bag.writer import BagWriteError, BagWriter, check_replaceable, CHUNK_SIZE

import yaml

PathLike = Union[str, os.PathLike]
# bytes of an MCAP Message record besides its payload: opcode 1, length 8, channel 2,
# sequence 4, log time 8, publish time 8
MESSAGE_RECORD_OVERHEAD = 31


class SplitBagWriter:
    """A bag written as consecutive MCAP files (see the module doc); BagWriter's surface."""

    def __init__(self, path: PathLike, *, overwrite: bool = False, compress: bool = False,
                 max_bytes: int = 0, max_duration_ns: int = 0,
                 chunk_size: int = CHUNK_SIZE) -> None:
        if max_bytes < 0 or max_duration_ns < 0:
            raise BagWriteError(f'split limits must be >= 0, got {max_bytes} bytes and '
                                f'{max_duration_ns} ns')
        self.path = Path(path)
        self.overwrite = overwrite
        self.compress = compress
        self.max_bytes = int(max_bytes)
        self.max_duration_ns = int(max_duration_ns)
        self.chunk_size = chunk_size
        self.custom_data: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.error: Optional[BagWriteError] = None
        self.files: list[str] = []              # the finished files, in order
        self._infos: list[dict] = []
        self._topics: dict[str, tuple] = {}
        self._tmp: Optional[Path] = None
        self._current: Optional[BagWriter] = None
        self._file_bytes = 0
        self._file_start: Optional[int] = None

    @property
    def bagdir(self) -> Path:
        """Return the bag directory while it is written (in the hidden .partial directory)."""
        return self._tmp / self.path.name

    def check_target(self) -> None:
        """Raise a BagError if the output path cannot be used (as BagWriter does)."""
        BagWriter(self.path, overwrite=self.overwrite).check_target()

    def open(self) -> None:  # noqa: A003 (the file-like verb, as BagWriter.open)
        """Check the target, make the hidden bag directory and start the first file."""
        self.check_target()
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.partial-',
                                              dir=self.path.parent))
            self.bagdir.mkdir()
        except OSError as exc:
            self.abort()
            raise BagWriteError(f'{self.path}: cannot create the bag: '
                                f'{exc.strerror or exc}') from None
        self._start_file()

    def _start_file(self) -> None:
        name = f'{self.path.name}_{len(self.files)}'
        writer = BagWriter(self._tmp / name, compress=self.compress, chunk_size=self.chunk_size)
        try:
            writer.open()
            for topic, (msgtype, qos, msgdef) in self._topics.items():
                writer.add_topic(topic, msgtype, qos=qos, msgdef=msgdef)
        except BagWriteError as exc:
            writer.abort()
            self.error = exc
            raise
        for key, value in self.custom_data.items():
            writer.set_custom_data(key, value)
        self._current = writer
        self._file_bytes = 0
        self._file_start = None

    def _finish_file(self) -> None:
        """Close the current file, move it into the bag, rewrite metadata.yaml."""
        writer, self._current = self._current, None
        done = writer.close()                   # a bag directory <name>_i with one file
        if writer.error is not None and self.error is None:
            self.error = writer.error
        info = yaml.safe_load((done / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        for name in info['relative_file_paths']:
            os.replace(done / name, self.bagdir / name)
            self.files.append(name)
        shutil.rmtree(done)
        self._infos.append(info)
        self._write_metadata()

    def _write_metadata(self) -> None:
        data = dict(self.custom_data)
        if self.error is not None:
            data['tskf_ros.incomplete'] = str(self.error)
        write_yaml(self.bagdir / 'metadata.yaml',
                   {'rosbag2_bagfile_information': merge_metadata(self._infos, data)})

    def set_custom_data(self, key: str, value: str) -> None:
        """Set a custom_data entry of metadata.yaml."""
        self.custom_data[key] = str(value)
        if self._current is not None:
            self._current.set_custom_data(key, value)

    def has_topic(self, topic: str) -> bool:
        """Say whether the topic was added."""
        return topic in self._topics

    def add_topic(self, topic: str, msgtype: str, *, qos: Sequence[Qos] = (),
                  msgdef: Optional[str] = None) -> None:
        """Add a topic to the current file and to every later one (see BagWriter.add_topic)."""
        if self.error is not None:
            raise self.error
        self._current.add_topic(topic, msgtype, qos=qos, msgdef=msgdef)
        self._topics[topic] = (msgtype, list(qos), msgdef)
        self.counts[topic] = 0

    def _split_due(self, log_time_ns: int) -> bool:
        if self._file_start is None:
            return False
        return ((self.max_bytes > 0 and self._file_bytes >= self.max_bytes)
                or (self.max_duration_ns > 0
                    and log_time_ns - self._file_start > self.max_duration_ns))

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """Write one message, first starting a new file if a limit is reached."""
        if self.error is not None:
            raise self.error
        t = int(log_time_ns)
        try:
            if self._split_due(t):
                self._finish_file()
                if self.error is not None:
                    raise self.error
                self._start_file()
            self._current.write(topic, t, data)
        except BagWriteError as exc:
            if self.error is None:
                self.error = exc
            raise
        except (OSError, BagError) as exc:
            self.error = BagWriteError(f'{self.path}: could not split the bag ({exc})')
            raise self.error from None
        self._file_bytes += len(data) + MESSAGE_RECORD_OVERHEAD
        if self._file_start is None:
            self._file_start = t
        self.counts[topic] += 1

    def flush(self) -> None:
        """Flush the current file (BagWriter.flush)."""
        if self._current is not None and self.error is None:
            try:
                self._current.flush()
            except BagWriteError as exc:
                self.error = exc
                raise

    def close(self) -> Path:
        """
        Finish the current file and the metadata, move the bag into place; return its path.

        After a write error what reached the disk is kept (each file sealed by BagWriter),
        `error` says what happened and the counts are those in the files.
        """
        if self._tmp is None:
            return self.path
        try:
            if self._current is not None:
                self._finish_file()
            elif not self._infos:
                raise BagWriteError('no file was written')
            self._write_metadata()
            if self.error is not None:
                self.counts = {name: 0 for name in self.counts}
                for entry in merge_metadata(self._infos)['topics_with_message_count']:
                    self.counts[entry['topic_metadata']['name']] = entry['message_count']
            if self.path.exists() or self.path.is_symlink():
                check_replaceable(self.path)
                os.replace(self.path, self._tmp / '.replaced')
            os.replace(self.bagdir, self.path)
            shutil.rmtree(self._tmp, ignore_errors=True)
        except (OSError, BagError, KeyError, TypeError, yaml.YAMLError) as exc:
            keep, self._tmp = self._tmp, None
            raise BagWriteError(f'{self.path}: could not finish the bag ({exc}); what was '
                                f'written is in {keep}') from None
        self._tmp = None
        return self.path

    def abort(self) -> None:
        """Delete everything written (nothing is left under the final name)."""
        if self._current is not None:
            self._current.abort()
            self._current = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
