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

"""SpillRows: the rows given back as written, and the temporary file never named nor left."""

import gc

from hypothesis import given, settings, strategies as st
import numpy as np
from open_files import open_files_in
import pytest

from tskf_ros.core.spill_rows import SpillRows

RECORD = np.dtype([('kind', np.int8), ('stamp', np.int64), ('value', np.float64, (2,))])


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 300), block=st.integers(1, 64), cut=st.integers(1, 50),
       seed=st.integers(0, 2**32 - 1))
def test_rows_come_back_as_written(n, block, cut, seed):
    rng = np.random.default_rng(seed)
    rows = np.zeros(n, RECORD)
    rows['kind'] = rng.integers(0, 2, n)
    rows['stamp'] = rng.integers(-2**62, 2**62, n)
    rows['value'] = rng.standard_normal((n, 2))
    with SpillRows(RECORD, block=block) as spill:
        for i in range(0, n, cut):
            if i % 2:
                spill.extend(rows[i:i + cut])
            else:
                for row in rows[i:i + cut]:
                    spill.append(row)
        assert len(spill) == n
        got = np.concatenate(list(spill.blocks())) if n else np.zeros(0, RECORD)
        assert got.tobytes() == rows.tobytes()
        start = int(rng.integers(0, n + 1))
        count = int(rng.integers(0, n - start + 1))
        assert spill.read(start, count).tobytes() == rows[start:start + count].tobytes()
        with pytest.raises(IndexError):
            spill.read(start, n - start + 1)


def test_a_sub_array_dtype_reads_back_as_a_shaped_array():
    x = np.arange(60.0).reshape(15, 2, 2)
    with SpillRows(np.dtype((np.float64, (2, 2))), block=4) as spill:
        spill.extend(x[:7])
        for row in x[7:]:
            spill.append(row)
        assert spill.read(3, 10).shape == (10, 2, 2)
        np.testing.assert_array_equal(np.concatenate(list(spill.blocks())), x)


def test_the_file_has_no_name_and_is_freed_on_close_and_on_error(tmp_path):
    spill = SpillRows(np.float64, block=8, directory=str(tmp_path))
    spill.extend(np.arange(7.0))
    assert open_files_in(tmp_path) == []           # no file for what fits in memory
    spill.extend(np.arange(7.0, 100.0))
    assert list(tmp_path.iterdir()) == []          # never a name a crash could leave
    assert len(open_files_in(tmp_path)) == 1
    spill.close()
    assert spill.closed and open_files_in(tmp_path) == []
    with pytest.raises(ValueError, match='closed'):
        spill.read(0, 1)
    with pytest.raises(KeyboardInterrupt):
        with SpillRows(np.float64, block=4, directory=str(tmp_path)) as spill:
            spill.extend(np.arange(10.0))
            assert len(open_files_in(tmp_path)) == 1
            raise KeyboardInterrupt
    assert spill.closed and open_files_in(tmp_path) == []
    # dropped without close (an exception unwinding the frames that held it)
    SpillRows(np.float64, block=4, directory=str(tmp_path)).extend(np.arange(10.0))
    gc.collect()
    assert open_files_in(tmp_path) == [] and list(tmp_path.iterdir()) == []
