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

"""The sweep's CSV table: a header, then one row flushed per finished task; locked, resumable."""

import csv
import fcntl
import os
from pathlib import Path
from typing import Optional, Union

import numpy as np


def cell(value: Optional[Union[bool, int, float, str]]) -> str:
    """Return a CSV cell: floats exact (repr), None and NaN empty."""
    if value is None:
        return ''
    if isinstance(value, float):
        return '' if not np.isfinite(value) else repr(value)
    return str(value)


class Table:
    """The CSV being written: header once, then one flushed row per finished task."""

    def __init__(self, path: Path, columns: list, resume: bool) -> None:
        self.path, self.columns = Path(path), columns
        self.done: set = set()
        self.rows: list = []
        # held while the sweep runs: a second sweep on the same table is refused
        self._lock = open(self.path, 'a')
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.close()
            raise ValueError(f'{self.path}: another sweep is writing this table') from None
        if resume and self.path.stat().st_size > 0:
            try:
                self._read_existing()
            except ValueError:
                self.close()
                raise
        else:
            self._lock.truncate(0)
            self._write_header()

    def _write_header(self) -> None:
        self._lock.write(','.join(self.columns) + '\n')
        self._lock.flush()
        os.fsync(self._lock.fileno())

    def close(self) -> None:
        """Release the table (its lock)."""
        self._lock.close()

    def _read_existing(self) -> None:
        data = self.path.read_bytes()
        if not data.endswith(b'\n'):        # a row cut by a kill: drop the partial line
            with open(self.path, 'r+b') as f:
                f.truncate(data.rfind(b'\n') + 1)
        with open(self.path, newline='') as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header is None:              # a header cut by a kill
                self._write_header()
            elif header != self.columns:
                raise ValueError(f"{self.path}: its columns are not this sweep's (other "
                                 '--set names or --fit); use --no-resume or another --out')
            for r in reader:
                if len(r) == len(self.columns):
                    self.rows.append(dict(zip(self.columns, r)))
                    self.done.add(r[0])

    def append(self, row: dict) -> None:
        """Append one row and flush it to disk."""
        values = [cell(row.get(c)) for c in self.columns]
        with open(self.path, 'a', newline='') as f:
            csv.writer(f).writerow(values)
            f.flush()
            os.fsync(f.fileno())
        self.rows.append(dict(zip(self.columns, values)))
        self.done.add(row['key'])
