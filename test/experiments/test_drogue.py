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

"""The drogue of Fang & de Callafon 2011 (Section IV): the README's numbers and its files."""

import json
from pathlib import Path

import numpy as np
import pytest

from tskf_ros.core import irregular as ir
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.experiments import drogue


def test_drogue_rms_velocity_error():
    r = drogue.run(drogue.DrogueConfig(seed=6))
    rms = r.rms()
    # README, seed 6: drogue velocity 0.0094 m/s (filter sigma 0.0088), flow 0.0095 m/s,
    # 0.0121 m/s without the inverse of eq. (27); to the printed digit
    assert rms['drogue_velocity'] == pytest.approx(0.0094, abs=5e-5)
    assert rms['filter_velocity_sd'] == pytest.approx(0.0088, abs=5e-5)
    assert rms['flow_velocity'] == pytest.approx(0.0095, abs=5e-5)
    assert rms['flow_velocity_without_inverse_27'] == pytest.approx(0.0121, abs=5e-5)
    assert rms['drogue_velocity'] < 0.015
    assert 0.4 < rms['drogue_velocity'] / rms['filter_velocity_sd'] < 1.6
    # the inverse of eq. (27) adds the slip the drogue velocity alone misses
    assert rms['flow_velocity'] < rms['flow_velocity_without_inverse_27']
    assert rms['flow_velocity'] < 0.015
    m = drogue.model_matrices(r.cfg)
    T = r.intervals()
    assert T[0] == 1 and T[-1] > 90
    assert ir.theorem1(m['A'], m['C'], T).stable


@pytest.mark.slow
def test_drogue_rms_over_seeds_1_to_20():
    # README: over seeds 1-20 the RMS error after the first dive ranges over 0.0047-0.0115
    v = [drogue.run(drogue.DrogueConfig(seed=seed)).rms()['drogue_velocity']
         for seed in range(1, 21)]
    assert min(v) == pytest.approx(0.0047, abs=5e-5)
    assert max(v) == pytest.approx(0.0115, abs=5e-5)


def test_drogue_main_writes_figure_and_summary(tmp_path, capsys):
    assert drogue.main(['--out', str(tmp_path), '--hours', '1.5']) == 0
    assert (tmp_path / 'drogue.png').stat().st_size > 10_000
    data = json.loads((tmp_path / 'drogue.json').read_text())
    # 1.5 h, seed 6: the numbers of the run itself, and Theorem 1 on its intervals
    rms = data['rms']
    assert rms['drogue_velocity'] == pytest.approx(0.007914, abs=5e-6)
    assert rms['flow_velocity'] == pytest.approx(0.008061, abs=5e-6)
    assert rms['flow_velocity_without_inverse_27'] == pytest.approx(0.011924, abs=5e-6)
    assert data['pathological_intervals'] == [] and data['degenerate_intervals'] == []
    assert data['theorem1_stable'] is True
    out = capsys.readouterr().out
    assert f"drogue {rms['drogue_velocity']:.5f} m/s" in out and 'stable: True' in out


def test_drogue_estimator_yaml_is_the_drogue_model():
    yaml = pytest.importorskip('yaml', reason='PyYAML is not installed')
    path = Path(__file__).resolve().parents[2] / 'config' / 'drogue_estimator.yaml'
    p = yaml.safe_load(path.read_text())['/**/timescale_estimator']['ros__parameters']
    kf = TimeScaleKalmanFilter(np.reshape(p['A'], (2, 2)), [p['C']], Q=[p['Q']], R=[p['R']],
                               G=p['G'], B=p['B'], x0=p['x0'], P0=np.reshape(p['P0'], (2, 2)),
                               transition=p['transition'])
    m = drogue.model_matrices(drogue.DrogueConfig())
    F, Qd, Bd = kf.transition_matrices(p['period'])
    np.testing.assert_allclose(F, m['A'], atol=1e-12)
    np.testing.assert_allclose(Bd, m['B'], atol=1e-12)
    # same velocity variance per step; R / mu is the 3 m fix at mu = period
    assert Qd[1, 1] == pytest.approx(m['Q'][1, 1], rel=1e-9)
    assert p['R'][0] / p['period'] == pytest.approx(m['R'][0, 0])
