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
"""The replay's columns: grown by blocks in memory, or streamed into a .npz numpy reads."""

import numpy as np
import pytest

from tskf_ros.bag.replay import columns
from tskf_ros.bag.replay.columns import CATEGORY, FileStore, MemoryStore, Table

SPEC = [('t', np.int64, ()), ('x', np.float64, (2,)), ('P', np.float64, (2, 2)),
        ('status', CATEGORY, ())]


def fill(store, rng, monkeypatch):
    """Write rows and blocks in a random mix; return the expected columns (plain numpy)."""
    monkeypatch.setattr(columns, 'BLOCK', 7)     # many hand-overs in a few rows
    table = Table(store, 'tab', SPEC, capacity=3)
    want = {'t': [], 'x': [], 'P': [], 'status': []}
    names = ['accepted', 'gap', '', 'rejected (a long reason)']
    for _ in range(40):
        k = int(rng.integers(1, 30))
        t = rng.integers(-2**62, 2**62, k)
        x, P = rng.normal(size=(k, 2)), rng.normal(size=(k, 2, 2))
        status = [names[i] for i in rng.integers(0, len(names), k)]
        if rng.random() < 0.5:
            for row in zip(t, x, P, status):
                table.row(row)
        elif rng.random() < 0.5:
            table.block(t, x, P, status)
        else:
            status = [names[int(rng.integers(0, len(names)))]] * k
            table.block(t, x, P, status[0])       # one value for every row
        for key, values in zip(want, (t, x, P, status)):
            want[key] += list(values)
    table.flush()
    return {f'tab.{k}': np.array(v, dtype=str if k == 'status' else None)
            for k, v in want.items()}


def test_memory_columns_hold_every_row_in_order(monkeypatch):
    store = MemoryStore()
    want = fill(store, np.random.default_rng(1), monkeypatch)
    got = store.arrays()
    assert set(got) == set(want)
    for key, value in want.items():
        assert got[key].dtype == value.dtype
        np.testing.assert_array_equal(got[key], value)      # exact: copied, not computed
        assert got[key].flags.owndata and got[key].base is None


def test_the_npz_holds_what_memory_holds_and_what_numpy_savez_writes(tmp_path, monkeypatch):
    (tmp_path / 'work').mkdir()
    store = FileStore(tmp_path / 'work')
    want = fill(store, np.random.default_rng(2), monkeypatch)
    extra = {'meta.topic': np.array('/received_power'), 'meta.none': np.array([], dtype=str)}
    store.write_npz(tmp_path / 'a.npz', extra)
    store.close()
    np.savez(tmp_path / 'b.npz', **want, **extra)
    with np.load(tmp_path / 'a.npz') as a, np.load(tmp_path / 'b.npz') as b:
        assert list(a.keys()) == list(b.keys())
        for key in b:
            assert a[key].dtype == b[key].dtype and a[key].shape == b[key].shape
            np.testing.assert_array_equal(a[key], b[key])


def test_empty_columns_keep_their_dtype_and_shape(tmp_path):
    store = MemoryStore()
    Table(store, 'tab', SPEC)
    got = store.arrays()
    assert got['tab.P'].shape == (0, 2, 2) and got['tab.t'].dtype == np.int64
    assert got['tab.status'].shape == (0,) and got['tab.status'].dtype.kind == 'U'
    files = FileStore(tmp_path)
    Table(files, 'tab', SPEC)
    files.write_npz(tmp_path / 'e.npz', {})
    files.close()
    with np.load(tmp_path / 'e.npz') as f:
        assert f['tab.P'].shape == (0, 2, 2) and f['tab.status'].shape == (0,)


def test_a_memory_column_grows_in_place_without_a_second_copy():
    store = MemoryStore()
    store.add('c', np.float64, (), capacity=0)
    for k in range(200):
        store.extend('c', np.full(1000, float(k)))
    out = store.arrays()['c']
    assert out.shape == (200_000,)
    np.testing.assert_array_equal(out[::1000], np.arange(200.0))
    with pytest.raises(KeyError):
        store.extend('c', np.zeros(1))      # the store gave its columns away
