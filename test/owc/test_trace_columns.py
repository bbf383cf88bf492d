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

"""The run's columns in temporary files: what was appended, and sums as np.sum's over arrays."""

from dataclasses import replace

import numpy as np
import pytest

from tskf_ros.core import noise_fit, spill_rows
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.nis_check import nis_summary
from tskf_ros.core.noise_fit import innovation_terms, Innovations, StepRecord
from tskf_ros.owc.trace_columns import InnovationColumns, TraceColumns


@pytest.mark.parametrize('p', [1, 2])
def test_innovations_in_blocks_are_the_arrays_kept_whole(p):
    # 40 000 innovations in uneven blocks, more than two blocks of the file's: the NIS,
    # log det S, log-likelihood and NIS check are those of the whole arrays, bit for bit
    rng = np.random.default_rng(p)
    n = 40_000
    e = rng.standard_normal((n, p)) * np.exp2(rng.uniform(-20, 20, (n, 1)))
    L = np.tril(rng.standard_normal((n, p, p))) + 3.0 * np.eye(p)
    S = L @ np.swapaxes(L, 1, 2) * np.exp2(rng.uniform(-20, 20, (n, 1, 1)))
    nis, log_det = innovation_terms(e, S)
    whole = Innovations(e, S, nis, log_det)
    cols = InnovationColumns(p)
    start = 0
    while start < n:
        step = int(rng.integers(1, 9000))
        cols.extend(e[start:start + step], S[start:start + step])
        start += step
    assert cols.count == whole.count == n
    assert (np.float64(cols.log_likelihood()).tobytes()
            == np.float64(whole.log_likelihood()).tobytes())
    assert cols.nis_summary() == nis_summary(whole.nis, p)
    for field in ('e', 'S', 'nis', 'log_det_S'):
        np.testing.assert_array_equal(getattr(cols, field), getattr(whole, field),
                                      err_msg=field)
    cols.close()


def test_no_innovations():
    cols = InnovationColumns(1)
    cols.extend(np.zeros((0, 1)), np.zeros((0, 1, 1)))
    assert cols.count == 0 and cols.log_likelihood() == 0.0
    assert cols.nis_summary()['n'] == 0 and cols.nis.shape == (0,)


def test_steps_come_back_as_appended_across_blocks():
    rng = np.random.default_rng(9)
    segments = []
    for n in (5, 20_000, 17_000):
        seg = []
        for _ in range(n):
            y = None if rng.random() < 0.2 else rng.standard_normal(2)
            u = None if rng.random() < 0.5 else rng.standard_normal(1)
            seg.append(StepRecord(float(rng.uniform(0.5, 2)), y, u,
                                  float(rng.uniform(0, 1)) if y is not None else 0.0))
        segments.append(seg)
    # the first step with no y and no u: their widths are set later, by the first present
    segments[0][0] = StepRecord(1.0, None, None)
    trace = TraceColumns()
    for i, seg in enumerate(segments):
        for rec in seg:
            trace.append(i, rec)
    assert len(trace) == 3 and trace.steps == 37_005
    assert trace.measurement_steps == sum(r.y is not None for s in segments for r in s)
    for seg, back in zip(segments, trace):
        assert len(back) == len(seg)
        for a, b in zip(seg, back):
            assert a.mu == b.mu and a.variance == b.variance
            for x, y in ((a.y, b.y), (a.u, b.u)):
                assert (x is None) == (y is None)
                if x is not None:
                    np.testing.assert_array_equal(x, y)
    rec = trace[1][-1]
    assert rec.mu == segments[1][-1].mu and trace[2][3].mu == segments[2][3].mu
    trace.close()


def test_the_likelihood_reads_the_columns_as_it_reads_the_records(monkeypatch):
    # innovation_blocks takes the TraceColumns a block of columns at a time (blocks of 64
    # rows here, the runs cut at their edges): the same e_k, S_k, bit for bit, as over
    # the same steps given as a list of StepRecords (gaps, sample variances, inputs)
    monkeypatch.setattr(spill_rows, 'BLOCK', 64)
    rng = np.random.default_rng(21)
    model = LinearModel('two', A=np.array([[0.0, 1.0], [-0.5, -0.2]]), C=np.eye(2),
                        Q=np.eye(2) * 0.1, R=np.eye(2) * 0.2, x0=np.zeros(2), P0=np.eye(2),
                        B=np.array([[1.0], [0.5]]))
    segments = []
    for n in (3, 700, 450):
        seg = []
        for _ in range(n):
            y = None if rng.random() < 0.1 else rng.standard_normal(2)
            u = rng.standard_normal(1) if rng.random() < 0.05 else None
            variance = float(rng.uniform(0.1, 1.0)) if rng.random() < 0.05 else 0.0
            seg.append(StepRecord(float(rng.uniform(0.009, 0.011)), y, u, variance))
        segments.append(seg)
    trace = TraceColumns()
    for i, seg in enumerate(segments):
        for rec in seg:
            trace.append(i, rec)
    for m in (model, replace(model, B=None)):
        listed = list(noise_fit.innovation_blocks(m, 'euler', segments, block=64))
        columns = list(noise_fit.innovation_blocks(m, 'euler', trace, block=64))
        for k in (0, 1):
            np.testing.assert_array_equal(np.concatenate([b[k] for b in columns]),
                                          np.concatenate([b[k] for b in listed]))
    trace.close()
