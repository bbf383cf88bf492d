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

"""python -m tskf_ros.experiments.smoothing: RMS table and figures on the sample bags."""

import numpy as np
import pytest

from tskf_ros.experiments import smoothing
from tskf_ros.experiments.bag_analysis import evaluate_bag
from tskf_ros.messages.estimator_interface import load_config


def test_writes_the_figure_and_the_table_for_the_cai_bag(tmp_path, capsys):
    assert smoothing.main(['--only', 'owc_cai_td_1hz', '--out', str(tmp_path)]) == 0
    assert (tmp_path / 'owc_cai_td_1hz_smoothed.png').stat().st_size > 10_000
    rows = [line for line in capsys.readouterr().out.splitlines()
            if line.startswith('| `owc_cai_td_1hz`')]
    assert len(rows) == 1
    rms = [float(cell) for cell in rows[0].split('|')[3:7]]
    assert np.isfinite(rms).all() and min(rms) > 0
    # T_d: 288 samples at whole seconds, the truth at every second: every estimate is scored
    assert rows[0].rstrip(' |').endswith('288 / 287 / 287')


def test_the_rms_is_taken_against_the_truth_at_the_same_stamps():
    bag = smoothing.BAGS[0]
    c = smoothing.compare(smoothing.REPO / 'bags', bag, smoothing.REPO / 'config')
    s = c.series['corrected']
    truth = dict(zip(np.round(c.truth_t, 9), c.truth_x))
    err = np.array([x - truth[round(t, 9)] for t, x in zip(s.t, s.x)])
    assert s.rms == np.sqrt(np.mean(err ** 2))
    # the last stepped point: x(T|T) is the filter's corrected estimate
    assert c.series['smoothed'].x[-1] == s.x[-1]


def test_a_missing_bag_is_one_line(tmp_path, capsys):
    assert smoothing.main(['--bags', str(tmp_path), '--out', str(tmp_path / 'o')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('smoothing: error: no bag')


def test_the_sweep_reports_the_smoothed_rms_of_the_replay():
    # evaluate_bag (the sweep's row) feeds the session from read_stream; the experiment
    # replays the bag: both must score the same smoothed estimates against the truth
    bag = smoothing.BAGS[0]
    config = load_config(smoothing.REPO / 'config' / bag.params)
    row = evaluate_bag(smoothing.REPO / 'bags' / bag.name, config)
    c = smoothing.compare(smoothing.REPO / 'bags', bag, smoothing.REPO / 'config')
    assert row['rms_smoothed'] == pytest.approx(c.series['smoothed'].rms, rel=1e-12)
    assert row['rms_corrected'] == pytest.approx(c.series['corrected'].rms, rel=1e-12)
