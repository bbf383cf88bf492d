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
Rows of one numpy dtype kept in a temporary file, read back a block at a time.

What an analysis must read again over a long bag (the events, the filter steps, the
innovations) would grow in memory with the bag; `SpillRows` keeps one block in memory
and the rest in an anonymous temporary file (`tempfile.TemporaryFile`: on Linux it has
no name from the start, so the system frees it when the file is closed or the process
ends, however it ends: an error, Ctrl-C, a kill).  Written and read with write and
pread, the file's pages are the page cache's, not the process's resident memory.  The
folder is tempfile's (TMPDIR, else /tmp); a row costs its dtype's itemsize there.

No ROS.
"""

import os
import tempfile
from typing import IO, Iterator, Optional

import numpy as np
from numpy.typing import DTypeLike, NDArray

__all__ = ['BLOCK', 'SpillRows']

# rows kept in memory and read back at a time
BLOCK = 16384


class SpillRows:
    """
    Rows of `dtype` appended at the end, read back in order a block at a time.

    block: rows kept in memory (default BLOCK); the file is made when they are first full.
    """

    def __init__(self, dtype: DTypeLike, block: Optional[int] = None,
                 directory: Optional[str] = None) -> None:
        # a row: one element of dtype (of dtype.base, shaped dtype.shape, for a sub-array)
        self.dtype = np.dtype(dtype)
        self._base, self._shape = self.dtype.base, self.dtype.shape
        self.block = int(BLOCK if block is None else block)
        self._buffer = self._empty(self.block)
        self._fill = 0
        self._written = 0       # rows in the file
        self._directory = directory
        self._file: Optional[IO[bytes]] = None      # made when the first block is full
        self._closed = False

    def _empty(self, rows: int) -> NDArray:
        return np.zeros((rows, *self._shape), self._base)

    def append(self, row: object) -> None:
        """Add a row (anything assignable to one element of the dtype)."""
        self._buffer[self._fill] = row
        self._fill += 1
        if self._fill == self.block:
            self._flush()

    def extend(self, rows: NDArray) -> None:
        """Add rows (an array of the dtype)."""
        rows = np.asarray(rows, dtype=self._base)
        i = 0
        while i < len(rows):
            take = min(self.block - self._fill, len(rows) - i)
            self._buffer[self._fill:self._fill + take] = rows[i:i + take]
            self._fill += take
            i += take
            if self._fill == self.block:
                self._flush()

    def _flush(self) -> None:
        if not self._fill:
            return
        if self._closed:
            raise ValueError('rows added to a closed SpillRows')
        if self._file is None:
            self._file = tempfile.TemporaryFile(dir=self._directory)
        data = self._buffer[:self._fill].reshape(-1).view(np.uint8).data
        offset = self._written * self.dtype.itemsize
        while len(data):
            done = os.pwrite(self._file.fileno(), data, offset)
            data, offset = data[done:], offset + done
        self._written += self._fill
        self._fill = 0

    def __len__(self) -> int:
        return self._written + self._fill

    def read(self, start: int, count: int) -> NDArray:
        """Return rows start .. start + count - 1 (a new array)."""
        if start < 0 or count < 0 or start + count > len(self):
            raise IndexError(f'rows {start}..{start + count - 1} of {len(self)}')
        out = self._empty(count)
        on_disk = max(0, min(count, self._written - start))
        if on_disk:
            if self._file is None or self._closed:
                raise ValueError('rows read from a closed SpillRows')
            view = out[:on_disk].reshape(-1).view(np.uint8).data
            offset = start * self.dtype.itemsize
            while len(view):
                done = os.preadv(self._file.fileno(), [view], offset)
                if done <= 0:
                    raise OSError(f'the temporary file ended {len(view)} bytes early')
                view, offset = view[done:], offset + done
        if count > on_disk:
            first = start + on_disk - self._written
            out[on_disk:] = self._buffer[first:first + count - on_disk]
        return out

    def blocks(self, start: int = 0, stop: Optional[int] = None) -> Iterator[NDArray]:
        """Yield rows start .. stop - 1 (default: all), a block at a time, in order."""
        stop = len(self) if stop is None else stop
        for first in range(start, stop, self.block):
            yield self.read(first, min(self.block, stop - first))

    def close(self) -> None:
        """Free the file (the rows are gone)."""
        self._closed = True
        if self._file is not None:
            self._file.close()

    @property
    def closed(self) -> bool:
        """Return whether the file is freed."""
        return self._closed

    def __enter__(self) -> 'SpillRows':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
