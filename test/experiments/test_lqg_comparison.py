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

"""The LQG-against-P comparison (tskf_ros.experiments.lqg_comparison): its JSON and PNG."""

import dataclasses
import json

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.experiments import lqg_comparison


def test_comparison_writes_both_controllers(tmp_path, capsys):
    out, png = tmp_path / 'c.json', tmp_path / 'c.png'
    assert lqg_comparison.main(['--runs', '3', '--steps', '30', '--betas', '0,14',
                                '--json', str(out), '--png', str(png)]) == 0
    data = json.loads(out.read_text())
    assert set(data['sweep']) == {'p', 'p_prior', 'lqg'} and len(data['sweep']['lqg']) == 2
    ratio = data['mean_abs_phi_ratio_lqg_over']['p_prior']['effort']
    assert ratio['ci95'][0] <= ratio['ratio'] <= ratio['ci95'][1]
    for point in data['sweep']['p_prior']:
        lo, hi = point['angular']['ci95']
        assert lo <= point['angular']['mean'] <= hi
    assert data['effort']['lqg']['noise_v'] == 1.0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_help_prints_and_exits_0(capsys):
    # argparse formats help strings with %: a literal one must be written %%
    with pytest.raises(SystemExit) as exc:
        lqg_comparison.main(['--help'])
    assert exc.value.code == 0
    assert 'write tracking % against beta' in capsys.readouterr().out


def test_p_with_the_clipped_prior_is_the_paper_p_but_for_p0():
    # the only difference between 'p' and 'p_prior' is P0: diag(100, 1000) -> diag(4, 25)
    assert lqg_comparison.EKF_CONFIGS['p'] == led.EKFConfig()
    assert lqg_comparison.EKF_CONFIGS['p_prior'] == led.EKFConfig(P0=((4.0, 0.0), (0.0, 25.0)))
    common = {'beta': 2.8, 'noise': 1.0, 'runs': 4, 'steps': 40, 'dt': 0.05, 'seed': 5}
    p, phi_p = lqg_comparison.simulate_point('p', **common)
    aligner = led.make_aligner('ekf', runs=4)
    traj = led.simulate_tracking(aligner, led.TrackingLinkConfig(beta=2.8, noise=1.0, steps=40),
                                 np.random.default_rng(5))
    np.testing.assert_allclose(phi_p, np.abs(led.wrap_degrees(traj.phi)).mean(axis=0),
                               rtol=1e-12)
    ratio = lqg_comparison.phi_ratio(phi_p, phi_p, 0)
    assert ratio == {'ratio': 1.0, 'ci95': [1.0, 1.0]}


def test_workers_give_the_sequential_results(tmp_path, capsys):
    outs = []
    for workers in ('1', '2'):
        out = tmp_path / f'w{workers}.json'
        assert lqg_comparison.main(['--runs', '3', '--steps', '30', '--betas', '0,14',
                                    '--ablation', '--workers', workers,
                                    '--json', str(out)]) == 0
        data = json.loads(out.read_text())
        data.pop('elapsed_s')
        outs.append(data)
    assert outs[0] == outs[1]


def test_points_in_parts_and_batches_are_each_part_alone_run_for_run():
    # the sequential path: each part (of at most 3 runs) on its own aligner, from its own
    # generator (part 0: the seed's, part k: [seed, k]); the points in parts side by side
    # (several drift rates and noise levels on one aligner), on one worker or two, give
    # the same numbers, run for run
    common = {'runs': 7, 'steps': 40, 'dt': 0.05, 'seed': 5}
    points = [lqg_comparison.point(name, beta=beta, noise=noise, **common)
              for beta, noise in ((0.0, 0.2), (14.0, 0.2), (2.8, 1.0))
              for name in lqg_comparison.CONTROLLERS]
    points.append(lqg_comparison.point('lqg', beta=14.0, noise=0.2,
                                       lqg=lqg_comparison.ABLATIONS['no_bank'], **common))
    alone = []
    for p in points:
        parts = []
        for k, start in enumerate(range(0, 7, 3)):
            part = dataclasses.replace(p, runs=min(3, 7 - start))
            aligner = lqg_comparison.COMPARISON.build([part], part.runs)
            traj = led.simulate_tracking(aligner, p.link,
                                         np.random.default_rng(5 if k == 0 else [5, k]))
            parts.append(lqg_comparison.run_values(traj, aligner.scan_offset))
        alone.append(lqg_comparison.COMPARISON.join(parts))
    for workers, batch in ((1, 3), (1, 10**6), (2, 6)):
        together = list(lqg_comparison.run_points(points, workers, part_runs=3,
                                                  batch_runs=batch))
        assert len(together) == len(points)
        for a, b in zip(alone, together):
            for field in dataclasses.fields(lqg_comparison.RunValues):
                np.testing.assert_array_equal(getattr(a, field.name), getattr(b, field.name),
                                              err_msg=field.name)


def test_a_point_of_at_most_one_part_is_simulate_point():
    # the first part draws what an undivided point draws from the seed
    common = {'beta': 14.0, 'noise': 0.2, 'runs': 5, 'steps': 40, 'dt': 0.05, 'seed': 2}
    record, phi = lqg_comparison.simulate_point('lqg', **common)
    (values,) = lqg_comparison.run_points([lqg_comparison.point('lqg', **common)], 1)
    np.testing.assert_array_equal(values.abs_phi, phi)
    assert lqg_comparison.point_record(14.0, 0.2, values, 2) == record


def test_the_bootstrap_in_rows_is_the_bootstrap_at_once(monkeypatch):
    # the index drawn a few rows at a time is the same numbers as (resamples, runs) at once
    rng = np.random.default_rng(9)
    a, b = rng.random(37), rng.random(37)
    index = np.random.default_rng(4).integers(0, 37, size=(lqg_comparison.BOOTSTRAP, 37))
    monkeypatch.setattr(lqg_comparison, 'BOOTSTRAP_CHUNK', 37 * 3 + 5)
    means_a, means_b = lqg_comparison.bootstrap_means([a, b], 4)
    np.testing.assert_array_equal(means_a, a[index].mean(axis=1))
    np.testing.assert_array_equal(means_b, b[index].mean(axis=1))
    ratio = lqg_comparison.phi_ratio(a, b, 2)
    ratios = a[index].mean(axis=1) / b[index].mean(axis=1)
    assert ratio['ci95'] == [float(v) for v in np.percentile(ratios, [2.5, 97.5])]


def test_a_dask_scheduler_gives_the_sequential_results(tmp_path, capsys):
    # the tasks on a Dask cluster's workers: the same numbers as on one process
    distributed = pytest.importorskip('dask.distributed')
    args = ['--runs', '3', '--steps', '30', '--betas', '0,14']
    outs = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        for extra in (['--workers', '1'], ['--scheduler', cluster.scheduler_address]):
            out = tmp_path / f'{len(outs)}.json'
            assert lqg_comparison.main(args + extra + ['--json', str(out)]) == 0
            data = json.loads(out.read_text())
            data.pop('elapsed_s')
            outs.append(data)
    assert outs[0] == outs[1]


def test_a_scheduler_not_reached_is_one_line(tmp_path, capsys):
    assert lqg_comparison.main(['--runs', '2', '--steps', '3', '--betas', '1',
                                '--scheduler', 'tcp://127.0.0.1:9']) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'cannot use the Dask scheduler at tcp://127.0.0.1:9' in err
