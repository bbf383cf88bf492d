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
from typing import Iterator, Optional

import numpy as np
from numpy.typing import DTypeLike, NDArray

__all__ = ['BLOCK', 'SpillRows']

# rows kept in memory and read back at a time
BLOCK = 16384


class SpillRows:
    """Rows of `dtype` appended at the end, read back in order a block at a time."""

    def __init__(self, dtype: DTypeLike, block: int = BLOCK,
                 directory: Optional[str] = None) -> None:
        self.dtype = np.dtype(dtype)
        self.block = int(block)
        self._buffer = np.zeros(self.block, self.dtype)
        self._fill = 0
        self._written = 0       # rows in the file
        self._file = tempfile.TemporaryFile(dir=directory)

    def append(self, row: object) -> None:
        """Add a row (anything assignable to one element of the dtype)."""
        self._buffer[self._fill] = row
        self._fill += 1
        if self._fill == self.block:
            self._flush()

    def extend(self, rows: NDArray) -> None:
        """Add rows (an array of the dtype)."""
        rows = np.asarray(rows, dtype=self.dtype)
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
        data = memoryview(self._buffer[:self._fill].view(np.uint8))
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
        out = np.empty(count, self.dtype)
        on_disk = max(0, min(count, self._written - start))
        if on_disk:
            view = memoryview(out[:on_disk].view(np.uint8))
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
        self._file.close()

    @property
    def closed(self) -> bool:
        """Return whether the file is freed."""
        return self._file.closed

    def __enter__(self) -> 'SpillRows':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
