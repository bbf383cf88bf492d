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
The columns of a replay's arrays, grown a block at a time: in memory, or on disk for a .npz.

A replay's arrays (ArraySink) are tables of rows, one row per message; each table keeps at
most BLOCK rows as Python tuples and then appends them, column by column, to its store:

- MemoryStore: one numpy array per column, grown in place (ndarray.resize: for a large
  array glibc's realloc moves pages, it does not copy them) and cut to length at the end;
  replay_arrays returns these, nothing else of the rows remains;
- FileStore: one raw file per column in a work directory, appended to; `write_npz` then
  streams them into a .npz (an uncompressed zip of .npy files, what numpy.savez writes),
  so that the memory held is a block per column whatever the length of the bag.

A column of a few repeated strings (a status, a reason) is kept as codes into its list of
categories and turned into a numpy str array only at the end (by blocks, on disk).
"""

import os
from pathlib import Path
import shutil
from typing import BinaryIO, Optional, Sequence
import zipfile

import numpy as np
from numpy.typing import DTypeLike, NDArray

__all__ = ['BLOCK', 'CATEGORY', 'ColumnStore', 'FileStore', 'MemoryStore', 'Table']

# rows a table keeps as tuples before they go to the store (a bound on what it holds)
BLOCK = 4096
# the dtype that marks a column of categories (strings kept as codes)
CATEGORY = 'category'
_CODE = np.dtype(np.int32)
# bytes of a raw column copied (or converted) at once into the .npz
_COPY = 1 << 20


class ColumnStore:
    """Where a table's columns go: `add` each column once, then `extend` it by blocks."""

    def __init__(self) -> None:
        self.specs: dict[str, tuple[np.dtype, tuple[int, ...]]] = {}
        self.lengths: dict[str, int] = {}
        self.categories: dict[str, list[str]] = {}

    def add(self, key: str, dtype: DTypeLike, shape: tuple[int, ...] = (),
            capacity: int = 0) -> None:
        """Add an empty column of rows of `shape` (CATEGORY: strings kept as codes)."""
        if dtype == CATEGORY:
            self.categories[key] = []
            dtype = _CODE
        self.specs[key] = (np.dtype(dtype), tuple(shape))
        self.lengths[key] = 0

    def extend(self, key: str, block: NDArray) -> None:  # pragma: no cover - abstract
        """Append rows (an array of shape (k, *shape) and the column's dtype)."""
        raise NotImplementedError

    def strings(self, key: str) -> NDArray:
        """Return the categories of a CATEGORY column as a numpy str array (for its codes)."""
        return np.array(self.categories[key], dtype=str)


class MemoryStore(ColumnStore):
    """Columns as numpy arrays in memory, grown in place; `arrays()` returns them."""

    def __init__(self) -> None:
        super().__init__()
        self.data: dict[str, NDArray] = {}

    def add(self, key: str, dtype: DTypeLike, shape: tuple[int, ...] = (),
            capacity: int = 0) -> None:
        """Add an empty column, with room for `capacity` rows (a guess; it grows)."""
        super().add(key, dtype, shape, capacity)
        dt, shape = self.specs[key]
        self.data[key] = np.empty((max(capacity, 0), *shape), dtype=dt)

    def extend(self, key: str, block: NDArray) -> None:
        """Append rows; grow the array by half again when it is full."""
        arr, n, k = self.data[key], self.lengths[key], len(block)
        if n + k > len(arr):
            arr.resize((max(n + k, len(arr) * 3 // 2, 1024), *arr.shape[1:]), refcheck=False)
        arr[n:n + k] = block
        self.lengths[key] = n + k

    def arrays(self) -> dict[str, NDArray]:
        """Return every column cut to its length (categories as str arrays); empty self."""
        out = {}
        for key in list(self.data):
            arr, n = self.data.pop(key), self.lengths[key]
            arr.resize((n, *arr.shape[1:]), refcheck=False)
            out[key] = self.strings(key)[arr] if key in self.categories else arr
        return out


class FileStore(ColumnStore):
    """Columns appended to raw files in `folder`; `write_npz` streams them into a .npz."""

    def __init__(self, folder: Path) -> None:
        super().__init__()
        self.folder = Path(folder)
        self.files: dict[str, BinaryIO] = {}

    def add(self, key: str, dtype: DTypeLike, shape: tuple[int, ...] = (),
            capacity: int = 0) -> None:
        """Add an empty column: a new raw file in the folder."""
        super().add(key, dtype, shape, capacity)
        self.files[key] = open(self.folder / f'column{len(self.files)}.raw', 'w+b')

    def extend(self, key: str, block: NDArray) -> None:
        """Append the rows' bytes to the column's file."""
        self.files[key].write(np.ascontiguousarray(block, dtype=self.specs[key][0]).data)
        self.lengths[key] += len(block)

    def write_npz(self, path: Path, extra: dict[str, NDArray],
                  order: Optional[Sequence[str]] = None) -> None:
        """Write every column (in `order`), then the `extra` arrays, as one .npz at path."""
        with open(path, 'wb') as f, \
                zipfile.ZipFile(f, 'w', zipfile.ZIP_STORED, allowZip64=True) as zf:
            for key in order or list(self.files):
                dtype, shape = self.specs[key]
                n, raw = self.lengths[key], self.files[key]
                raw.flush()
                raw.seek(0)
                with zf.open(f'{key}.npy', 'w', force_zip64=True) as out:
                    if key in self.categories:
                        self._write_categories(out, raw, n, self.strings(key))
                    else:
                        _header(out, dtype, (n, *shape))
                        shutil.copyfileobj(raw, out, _COPY)
            for key, arr in extra.items():
                with zf.open(f'{key}.npy', 'w', force_zip64=True) as out:
                    np.lib.format.write_array(out, np.asanyarray(arr), allow_pickle=False)
            f.flush()
            os.fsync(f.fileno())

    @staticmethod
    def _write_categories(out: BinaryIO, raw: BinaryIO, n: int, names: NDArray) -> None:
        """Write a CATEGORY column's codes as a str array, a block at a time."""
        if not len(names):
            names = np.array([''], dtype=str)
        _header(out, names.dtype, (n,))
        step = _COPY // _CODE.itemsize
        for _ in range(0, n, step):
            codes = np.frombuffer(raw.read(step * _CODE.itemsize), dtype=_CODE)
            out.write(names[codes].data)

    def close(self) -> None:
        """Close the column files (the folder is the caller's to delete)."""
        for f in self.files.values():
            f.close()
        self.files.clear()


def _header(out: BinaryIO, dtype: np.dtype, shape: tuple[int, ...]) -> None:
    """Write the .npy header of a C-ordered array of dtype and shape (format 1.0 or 2.0)."""
    header = {'descr': np.lib.format.dtype_to_descr(dtype), 'fortran_order': False,
              'shape': shape}
    try:
        np.lib.format.write_array_header_1_0(out, header)
    except ValueError:          # a header over 64 KiB: format 2.0
        np.lib.format.write_array_header_2_0(out, header)


class Table:
    """
    The rows of one kind of output ('sample', 'estimate/predicted', ...) going to a store.

    columns: (name, dtype or CATEGORY, shape of a row's value); the keys are
    '<table>.<name>'.  `row` keeps a row (a tuple in the order of the columns) and hands
    BLOCK of them on at a time; `block` hands on whole columns (after the rows kept, so
    the order stays that of the calls).
    """

    def __init__(self, store: ColumnStore, name: str,
                 columns: Sequence[tuple[str, DTypeLike, tuple[int, ...]]],
                 capacity: int = 0) -> None:
        self.store = store
        self.keys = [f'{name}.{column}' for column, _, _ in columns]
        self.rows: list[tuple] = []
        self._codes: dict[int, dict[str, int]] = {}
        for i, ((_, dtype, shape), key) in enumerate(zip(columns, self.keys)):
            store.add(key, dtype, shape, capacity)
            if dtype == CATEGORY:
                self._codes[i] = {}

    def row(self, values: tuple) -> None:
        """Keep one row; hand BLOCK rows on to the store."""
        self.rows.append(values)
        if len(self.rows) >= BLOCK:
            self.flush()

    def block(self, *columns: object) -> None:
        """
        Hand on whole columns (array-likes of equal length, in the order of the columns).

        A str for a CATEGORY column is that value in every row (the first column's length).
        """
        self.flush()
        k = len(columns[0])     # type: ignore[arg-type]
        for i, (key, values) in enumerate(zip(self.keys, columns)):
            if isinstance(values, str):
                self._constant(i, key, values, k)
            else:
                self._extend(i, key, values)

    def flush(self) -> None:
        """Hand the rows kept on to the store."""
        if not self.rows:
            return
        rows, self.rows = self.rows, []
        for i, (key, values) in enumerate(zip(self.keys, zip(*rows))):
            self._extend(i, key, values)

    def _extend(self, i: int, key: str, values: object) -> None:
        codes = self._codes.get(i)
        if codes is not None:
            names = self.store.categories[key]
            values = [codes[v] if v in codes else _new_code(codes, names, v) for v in values]
        dtype, shape = self.store.specs[key]
        block = np.asarray(values, dtype=dtype)
        self.store.extend(key, block.reshape((-1, *shape)))

    def _constant(self, i: int, key: str, value: str, k: int) -> None:
        codes = self._codes[i]
        code = codes[value] if value in codes else _new_code(
            codes, self.store.categories[key], value)
        self.store.extend(key, np.full(k, code, dtype=_CODE))


def _new_code(codes: dict[str, int], names: list[str], value: str) -> int:
    """Give a new category its code."""
    codes[value] = len(names)
    names.append(str(value))
    return codes[value]
