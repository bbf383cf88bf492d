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

"""alignment_mc --axes 2 (tskf_ros.experiments.alignment_mc_two_axis): its JSON and its CLI."""

import json
import os

import numpy as np
import pytest

from tskf_ros.experiments import alignment_mc, alignment_mc_two_axis, alignment_pat
from tskf_ros.experiments.alignment_ablation_report import wilson
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig
from tskf_ros.led.two_axis.pan_tilt_baselines import FourPointAveraging, TwoAxisHillClimbing
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt
from tskf_ros.led.two_axis.radial_response import RadialResponse

ONE_AXIS_KEYS = {'angular', 'measure'} | set(alignment_pat.empty_record())


def test_two_axes_write_the_one_axis_keys_and_per_axis_errors(tmp_path, capsys):
    out, png = tmp_path / 'a.json', tmp_path / 'a.png'
    assert alignment_mc.main(['--axes', '2', '--runs', '6', '--steps', '40', '--workers', '1',
                              '--noise-levels', '0.5,1.5', '--json', str(out),
                              '--png', str(png)]) == 0
    data = json.loads(out.read_text())
    assert {'noise_levels', 'results', 'config', 'elapsed_s'} <= set(data)
    assert data['noise_levels'] == [0.5, 1.5] and data['config']['axes'] == 2
    assert list(data['results']) == alignment_mc_two_axis.default_methods()
    assert {'hill_climbing', 'four_point'} < set(data['results'])
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    for name, got in data['results'].items():
        assert ONE_AXIS_KEYS <= set(got), name
        assert set(got['rms_error_deg']) == {'azimuth', 'elevation'}
        for key in ('angular', 'measure'):
            for i, mean in enumerate(got[key]['mean']):
                lo, hi = got[key]['ci95'][i]
                assert lo <= mean + 1e-9 and mean <= hi + 1e-9
    # a supervised method records its declared losses (a false-alarm rate), a plain one not
    if 'conical_ekf_pat' in data['results']:
        assert data['results']['conical_ekf_pat']['false_alarms_per_1000s'][0] is not None
    assert data['results']['hill_climbing']['false_alarms_per_1000s'] == [None, None]
    # no window ends within 40 samples (a count, not null); the baselines have no smoother
    for name in set(data['results']) - {'hill_climbing', 'four_point'}:
        assert data['results'][name]['smoothing_failures'] == [0, 0], name
    assert data['results']['hill_climbing']['smoothing_failures'] == [None, None]
    # the baselines' numbers, from the closed loop written out here: seed 0 at each level
    for i, noise in enumerate((0.5, 1.5)):
        link = PanTiltLinkConfig(beta=1.2, steps=40, noise=noise, offset0=5.0)
        for name, aligner in (('hill_climbing', TwoAxisHillClimbing(runs=6)),
                              ('four_point', FourPointAveraging(runs=6))):
            traj = simulate_pan_tilt(aligner, link, np.random.default_rng(0))
            got = data['results'][name]
            inside = traj.theta <= 15.0
            tracked = 100.0 * inside.mean(axis=0)
            assert got['angular']['mean'][i] == pytest.approx(tracked.mean(), abs=1e-9)
            assert got['angular']['std'][i] == pytest.approx(tracked.std(), abs=1e-9)
            measure = 100.0 * (traj.clean >= 0.6).mean(axis=0)
            assert got['measure']['mean'][i] == pytest.approx(measure.mean(), abs=1e-9)
            lost = int(np.count_nonzero(~inside[-1]))
            assert got['lost_at_end'][i] == pytest.approx(lost / 6, abs=1e-12)
            assert got['lost_at_end_ci95'][i] == pytest.approx(list(wilson(lost, 6)), abs=1e-12)
            for axis, name_of_axis in enumerate(('azimuth', 'elevation')):
                rms = np.sqrt(np.mean(traj.error[:, :, axis] ** 2, axis=0))
                assert got['rms_error_deg'][name_of_axis]['mean'][i] == \
                    pytest.approx(rms.mean(), rel=1e-12)
    err = capsys.readouterr().err
    assert 'noise 1.50 (2/2)' in err and f'wrote {out}' in err


def test_a_cold_start_is_recorded_and_the_acquisition_counted(tmp_path, capsys):
    out = tmp_path / 'a.json'
    assert alignment_mc.main(['--axes', '2', '--runs', '5', '--steps', '60', '--workers', '1',
                              '--noise-levels', '0', '--cold-start', '30',
                              '--methods', 'four_point', '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert data['config']['cold_start_deg'] == 30.0
    got = data['results']['four_point']
    within = got['acquired_within_10s'][0]
    assert within is not None and 0.0 <= within <= 1.0
    assert got['acquired_within_10s_ci95'][0] == pytest.approx(
        list(wilson(round(within * 5), 5)), abs=1e-12)


def test_jittered_stamps_and_dropouts_reach_the_link(tmp_path):
    # a method's numbers on jittered stamps with dropouts are those of the closed loop on
    # the link with the same jitter and dropout, written out here; exact stamps differ
    out = tmp_path / 'a.json'
    assert alignment_mc.main(['--axes', '2', '--runs', '4', '--steps', '60', '--workers', '1',
                              '--noise-levels', '1', '--jitter', '0.02', '--dropout', '0.1',
                              '--methods', 'four_point', '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert data['config']['jitter_s'] == 0.02 and data['config']['dropout'] == 0.1
    got = data['results']['four_point']['angular']['mean'][0]
    runs = {}
    for jitter in (0.02, 0.0):
        link = PanTiltLinkConfig(beta=1.2, steps=60, noise=1.0, offset0=5.0, jitter=jitter,
                                 dropout=0.1)
        traj = simulate_pan_tilt(FourPointAveraging(runs=4), link, np.random.default_rng(0))
        runs[jitter] = traj
    assert got == pytest.approx(100.0 * (runs[0.02].theta <= 15.0).mean(), abs=1e-9)
    steps = np.diff(runs[0.02].t)
    assert steps.min() < 0.05 - 0.005 and steps.max() > 0.05 + 0.005 and steps.min() > 0.0
    assert np.isnan(runs[0.02].z).mean() == pytest.approx(0.1, abs=0.05)
    assert not np.allclose(runs[0.02].theta, runs[0.0].theta)


def test_a_jitter_of_half_a_step_is_one_line_and_exit_2(capsys):
    # stamps k dt + U(-S, S) would reorder from S = dt/2 on: refused before the run
    assert alignment_mc.main(['--axes', '2', '--runs', '2', '--steps', '10',
                              '--noise-levels', '1', '--jitter', '0.025']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == 'alignment_mc: jitter must be in [0, dt/2), got 0.025', err


def test_one_axis_is_the_default(tmp_path, capsys):
    out = tmp_path / 'a.json'
    assert alignment_mc.main(['--runs', '2', '--steps', '20', '--noise-levels', '0.5',
                              '--algorithms', 'ekf', '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert 'axes' not in data['config'] and set(data['results']) == {'ekf'}


@pytest.mark.parametrize('argv, message', [
    (['--axes', '3'], 'argument --axes: invalid choice: 3 (choose from 1, 2)'),
    (['--axes', '2', '--methods', 'nope'], "--methods: unknown ['nope']"),
    (['--axes', '2', '--cold-start', '-1'],
     'argument --cold-start: must be a finite number in [0, 60]'),
    (['--axes', '2', '--runs', '0'], 'argument --runs: must be in'),
    (['--axes', '2', '--dim-radius', '15'],
     'argument --dim-radius: must be a finite number in [0, 14.9]'),
    (['--axes', '2', '--wide', 'nan'], 'argument --wide: must be a finite number in [0, 90]'),
    (['--axes', '2', '--smooth-after', '401'], 'argument --smooth-after: must be'),
    (['--axes', '2', '--smooth-every', '-1'], 'argument --smooth-every: must be'),
    (['--axes', '2', '--json', '/'], '--json /: / is a folder'),
    (['--axes', '2', '--png', 'FILE/a.png'], 'is not a folder'),
    # a FIFO (or a device) is not replaced by a plain file; a name too long for the file
    # system is found before the run, not after it
    (['--axes', '2', '--json', 'FIFO'], 'fifo is not a plain file'),
    (['--axes', '2', '--json', 'DIR/' + 'x' * 300 + '.json'], 'cannot write in'),
])
def test_a_bad_argument_is_one_line_and_exit_2(argv, message, capsys, tmp_path):
    # FILE: a file where a folder should be; FIFO: a named pipe; DIR: a folder
    (tmp_path / 'file').write_text('')
    os.mkfifo(tmp_path / 'fifo')
    argv = [a.replace('FILE', str(tmp_path / 'file')).replace('FIFO', str(tmp_path / 'fifo'))
            .replace('DIR', str(tmp_path)) for a in argv]
    with pytest.raises(SystemExit) as info:
        alignment_mc.main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and 'Traceback' not in '\n'.join(err), err


def test_an_output_that_cannot_be_written_after_the_run_is_one_line(tmp_path, capsys,
                                                                    monkeypatch):
    # the folder checked before the run, then gone read-only (a disk that filled): one
    # line, exit 1, and nothing left half-written
    out = tmp_path / 'a.json'

    def refuse(path, data):
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(alignment_mc_two_axis.output, 'write_json', refuse)
    assert alignment_mc.main(['--axes', '2', '--runs', '2', '--steps', '20', '--noise-levels',
                              '0.5', '--methods', 'four_point', '--json', str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == ('alignment_mc: cannot write the output: [Errno 28] No space left on '
                       'device') and 'Traceback' not in '\n'.join(err)
    assert list(tmp_path.iterdir()) == []


def test_a_fifo_is_not_replaced_by_an_output(tmp_path):
    fifo = tmp_path / 'f.json'
    os.mkfifo(fifo)
    with pytest.raises(OSError, match='is not a plain file'):
        alignment_mc_two_axis.output.write_json(fifo, {'a': 1})
    assert fifo.is_fifo() and sorted(p.name for p in tmp_path.iterdir()) == ['f.json']


def test_the_numbers_do_not_depend_on_the_workers(tmp_path, capsys):
    # each point starts its own generator from the seed: 1 and 2 processes agree
    data = []
    for workers in ('1', '2'):
        out = tmp_path / f'w{workers}.json'
        assert alignment_mc.main(['--axes', '2', '--runs', '3', '--steps', '30',
                                  '--noise-levels', '0.5,1', '--methods',
                                  'hill_climbing,four_point', '--workers', workers,
                                  '--json', str(out)]) == 0
        data.append(json.loads(out.read_text())['results'])
    assert data[0] == data[1]


def test_a_dask_scheduler_gives_the_local_results_run_for_run(tmp_path, capsys):
    # the points on a Dask cluster's workers: per run the numbers of one process, and the
    # same JSON
    distributed = pytest.importorskip('dask.distributed')
    points = [alignment_mc_two_axis.Point(name, 4, PanTiltLinkConfig(steps=40, noise=noise), 3,
                                          alignment_mc_two_axis.RadialResponse(), False)
              for noise in (0.5, 1.0) for name in ('conical_ekf_pat', 'four_point')]
    argv = ['--axes', '2', '--runs', '3', '--steps', '30', '--noise-levels', '0.5,1',
            '--methods', 'conical_ekf_pat,hill_climbing']
    local = list(alignment_mc_two_axis.run_points(points, 1))
    data = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = list(alignment_mc_two_axis.run_points(points, 1, cluster.scheduler_address))
        for extra in (['--workers', '1'], ['--scheduler', cluster.scheduler_address]):
            out = tmp_path / f'{len(data)}.json'
            assert alignment_mc.main(argv + extra + ['--json', str(out)]) == 0
            data.append(json.loads(out.read_text()))
    assert len(remote) == len(local) == 4
    for a, b in zip(local, remote):
        for field in ('angular', 'measure', 'rms'):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
        assert a.metrics['lost_at_end'] == b.metrics['lost_at_end']
        np.testing.assert_array_equal(a.metrics['acquisition'].times,
                                      b.metrics['acquisition'].times)
    for d in data:
        d.pop('elapsed_s')
    assert data[0] == data[1]


def test_a_scheduler_not_reached_is_one_line_and_exit_1(capsys):
    assert alignment_mc.main(['--axes', '2', '--runs', '2', '--steps', '3', '--noise-levels',
                              '1', '--methods', 'hill_climbing',
                              '--scheduler', 'tcp://127.0.0.1:9']) == 1
    err = [line for line in capsys.readouterr().err.splitlines()
           if not line.startswith('[alignment_mc]')]
    assert len(err) == 1, err
    assert err[0].startswith('alignment_mc: cannot use the Dask scheduler at tcp://127.0.0.1:9')


def test_the_scan_circle_wide_prior_and_smoother_reach_the_ekf_and_the_json(tmp_path, capsys):
    # --dim-radius (6.5 by default; 0 turns it off) changes the supervised EKF's runs (the
    # scan widens when dim) and is recorded; the baselines do not scan a circle and are
    # the same; so do --wide (0 by default), the runs with a wide prior regressed, and
    # --smooth-after (100 by default, past these 80 steps; 40 smooths within them) and
    # --smooth-every (50 by default, past them after 40; 20 smooths again at 60 and 80)
    data = []
    for extra in (['--dim-radius', '0'], ['--dim-peak', '2.5'], ['--wide', '2.5'],
                  ['--smooth-after', '40'], ['--smooth-after', '40', '--smooth-every', '20']):
        out = tmp_path / f'{len(data)}.json'
        assert alignment_mc.main(['--axes', '2', '--runs', '20', '--steps', '80', '--workers',
                                  '1', '--noise-levels', '1.5', '--methods',
                                  'conical_ekf_pat,four_point', '--json', str(out)]
                                 + extra) == 0
        data.append(json.loads(out.read_text()))
    assert data[0]['config']['dim_radius_deg'] == 0.0
    assert data[1]['config']['dim_radius_deg'] == 6.5
    assert data[1]['config']['dim_peak_v'] == 2.5
    assert [d['config']['wide_deg'] for d in data] == [0.0, 0.0, 2.5, 0.0, 0.0]
    assert [d['config']['smooth_after'] for d in data] == [100, 100, 100, 40, 40]
    assert [d['config']['smooth_every'] for d in data] == [50, 50, 50, 50, 20]
    a, b, c, e, f = (d['results'] for d in data)
    assert a['four_point'] == b['four_point'] == c['four_point'] == e['four_point']
    assert f['four_point'] == e['four_point']
    assert f['conical_ekf_pat']['rms_error_deg'] != e['conical_ekf_pat']['rms_error_deg']
    assert e['conical_ekf_pat']['rms_error_deg'] != b['conical_ekf_pat']['rms_error_deg']
    assert a['conical_ekf_pat']['rms_error_deg'] != b['conical_ekf_pat']['rms_error_deg']
    assert c['conical_ekf_pat']['rms_error_deg'] != b['conical_ekf_pat']['rms_error_deg']


def test_a_failed_smoothing_is_counted_in_the_point_result(monkeypatch):
    """Each window whose smoothing raises is one failure of the point (all runs at once)."""
    from tskf_ros.led.two_axis import conical_ekf

    def broken(filt, record):
        raise np.linalg.LinAlgError('not positive definite')
    monkeypatch.setattr(conical_ekf, 'smooth_window', broken)
    link = PanTiltLinkConfig(beta=1.2, steps=23, noise=1.0, offset0=5.0)
    ekf = ConicalEKFConfig(smooth_after=5, smooth_every=6)      # windows end at 5, 11, 17, 23
    point = alignment_mc_two_axis.Point('conical_ekf', 4, link, 0, RadialResponse(), True, ekf)
    assert alignment_mc_two_axis.run_point(point).smoothing_failures == 4
