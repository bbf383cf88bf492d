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

"""A bag split into several MCAP files by size or duration, as `ros2 bag record -b/-d`."""

import os
from pathlib import Path
import re
import shutil
import tempfile
from typing import Optional, Sequence, Union

from rosbags.interfaces import Qos

from tskf_ros.bag.bag_metadata import file_metadata, merge_metadata, write_yaml
from tskf_ros.bag.mcap_file import scan_mcap, seal_mcap
from tskf_ros.bag.reader import BagError
from tskf_ros.bag.writer import BagWriteError, BagWriter, check_replaceable, CHUNK_SIZE

import yaml

PathLike = Union[str, os.PathLike]
# bytes of an MCAP Message record besides its payload: opcode 1, length 8, channel 2,
# sequence 4, log time 8, publish time 8
MESSAGE_RECORD_OVERHEAD = 31
# disk space held back while recording (a file of zeros in the hidden directory) and given
# back before the bag is finished: when the disk fills, the last file's summary and the
# metadata still fit (the summary of 1000 chunks is about 100 kB)
RESERVE = '.reserve'
RESERVE_BYTES = 1 << 20
# the file of a split bag that a failed split left in the hidden directory: the file being
# finished (BagWriter's own hidden directory) or finished but not yet moved into the bag
_NUMBERED_PART = re.compile(r'^(?:\.(?P<hidden>.+_\d+)\.partial-[^/]+|(?P<done>.+_\d+))$')


def adopt_split_files(partial: Path, bagdir: Path) -> list[Path]:
    """
    Move into bagdir the files of a split bag left beside it in its hidden directory.

    A split bag is written in partial (`.NAME.partial-XXXX`) as the bag directory NAME and,
    for the file in progress, a bag NAME_<n> of its own (in BagWriter's hidden
    `.NAME_<n>.partial-YYYY`, then moved beside NAME once closed, then its file moved into
    NAME).  A crash or a full disk between these steps leaves NAME_<n>.mcap in one of them;
    this moves each such file into bagdir (never over a file there) and removes the
    directories it leaves empty (their metadata.yaml of the one file too).  Returns the
    files moved, in the order of n.
    """
    moved = []
    for entry in sorted(partial.iterdir()) if partial.is_dir() else []:
        match = _NUMBERED_PART.match(entry.name)
        name = match and (match['hidden'] or match['done'])
        if not name or not entry.is_dir() or entry == bagdir \
                or not re.fullmatch(rf'{re.escape(bagdir.name)}_\d+', name):
            continue
        inner = entry / name if match['hidden'] else entry
        source, target = inner / f'{name}.mcap', bagdir / f'{name}.mcap'
        if not source.is_file() or target.exists():
            continue
        os.replace(source, target)
        moved.append(target)
        for leftover in (inner / 'metadata.yaml', inner / '.metadata.yaml.tmp'):
            leftover.unlink(missing_ok=True)
        for folder in (inner, entry):
            try:
                folder.rmdir()          # only if empty: nothing else is deleted
            except OSError:
                pass
    return sorted(moved, key=lambda p: int(p.stem.rpartition('_')[2]))


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
        self._hold_reserve()
        self._start_file()

    def _hold_reserve(self) -> None:
        """Hold RESERVE_BYTES of the disk back (not on a disk too full for it already)."""
        try:
            fd = os.open(self._tmp / RESERVE, os.O_WRONLY | os.O_CREAT, 0o600)
            try:
                os.posix_fallocate(fd, 0, RESERVE_BYTES)
            finally:
                os.close(fd)
        except OSError:
            (self._tmp / RESERVE).unlink(missing_ok=True)

    def _release_reserve(self) -> None:
        if self._tmp is not None:
            (self._tmp / RESERVE).unlink(missing_ok=True)

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
        try:
            done = writer.close()               # a bag directory <name>_i with one file
        except BagWriteError as exc:            # its file is left for close() to take in
            if writer.error is not None:
                raise self._outer(writer.error) from None
            cause = re.search(r'could not finish the bag \((.*?)\); ', str(exc))
            raise BagWriteError(f'{self.path}: could not finish {writer.path.name} when '
                                f'splitting ({cause[1] if cause else exc})') from None
        if writer.error is not None and self.error is None:
            self.error = writer.error
        info = yaml.safe_load((done / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        for name in info['relative_file_paths']:
            os.replace(done / name, self.bagdir / name)
            self.files.append(name)
        shutil.rmtree(done)
        self._infos.append(info)
        self._write_metadata()

    def _outer(self, exc: BagWriteError) -> BagWriteError:
        """Return a file's error said of the bag (the file's hidden path tells a user nothing)."""
        if not str(exc).startswith(str(self._tmp)):
            return exc
        return type(exc)(f'{self.path}: {str(exc).split(": ", 1)[-1]}')

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
                self.error = self._outer(exc)
            raise self.error from None
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
                self.error = self._outer(exc)
                raise self.error from None

    def close(self) -> Path:
        """
        Finish the current file and the metadata, move the bag into place; return its path.

        After a write error what reached the disk is kept (each file sealed by BagWriter),
        `error` says what happened and the counts are those in the files.
        """
        if self._tmp is None:
            return self.path
        self._release_reserve()             # the room to finish in, on a full disk
        try:
            if self._current is not None:
                try:
                    self._finish_file()
                except BagWriteError as exc:    # kept in the hidden directory: adopted
                    self.error = self.error or exc
            self._adopt_leftovers()
            if not self._infos:
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

    def _adopt_leftovers(self) -> None:
        """Take into the bag the file that a failed split or close left (sealed)."""
        from tskf_ros.bag.reindex import is_closed     # reindex imports this module
        for mcap in adopt_split_files(self._tmp, self.bagdir):
            if not is_closed(mcap):
                seal_mcap(mcap)
            self.files.append(mcap.name)
            self._infos.append(file_metadata(mcap, stats=scan_mcap(mcap)))

    def abort(self) -> None:
        """Delete everything written (nothing is left under the final name)."""
        if self._current is not None:
            self._current.abort()
            self._current = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None
