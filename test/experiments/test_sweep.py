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

"""sweep: bags x settings on a Dask LocalCluster, a damaged bag in the set, resume."""

import csv
import logging
import math
from pathlib import Path
import shutil
import socket
import warnings

import pytest
from stderr_lines import one_line
from tskf_ros.experiments import sweep, sweep_table, sweep_tasks
from tskf_ros.experiments.bag_analysis import METRICS
from tskf_ros.messages.estimator_interface import default_parameters

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / 'bags' / 'owc_cai_td_1hz'
PARAMS = REPO / 'config' / 'owc_estimator.yaml'
SETS = [('R', [[1.0], [100.0]]), ('transition', ['euler', 'exact'])]


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """Two copies of the 1 Hz sample bag, the drogue bag and a truncated copy."""
    d = tmp_path_factory.mktemp('fleet')
    for name in ('a', 'b'):
        shutil.copytree(SAMPLE, d / 'terminal' / name)
    shutil.copytree(REPO / 'bags' / 'drogue', d / 'terminal' / 'drogue')
    damaged = d / 'terminal' / 'damaged'
    shutil.copytree(SAMPLE, damaged)
    mcap = damaged / 'owc_cai_td_1hz.mcap'
    # a third: inside the (one, zstd) chunk; a half now cuts only the summary section
    mcap.write_bytes(mcap.read_bytes()[:mcap.stat().st_size // 3])
    return d


def rows_by_key(rows):
    return {(r['bag'], r['R'], r['transition']): r for r in rows}


def assert_same(a, b, rel=1e-12):
    assert a.keys() == b.keys()
    for key in a:
        for col, va in a[key].items():
            vb = b[key][col]
            if col == 'seconds':
                continue
            try:
                fa, fb = float(va), float(vb)
            except ValueError:
                assert va == vb, (key, col)
                continue
            assert math.isclose(fa, fb, rel_tol=rel, abs_tol=0.0) or (
                math.isnan(fa) and math.isnan(fb)), (key, col, va, vb)


def test_find_bags_takes_directories_globs_and_bags(bags):
    found = sweep_tasks.find_bags([str(bags)])
    assert [Path(b).name for b in found] == ['a', 'b', 'damaged', 'drogue']
    assert sweep_tasks.find_bags([str(bags / 'terminal' / '[ab]')]) == found[:2]
    assert sweep_tasks.find_bags([str(bags / 'terminal' / 'a')]) == found[:1]


def test_parse_setting_types_values_as_the_parameter():
    d = default_parameters()
    assert sweep_tasks.parse_setting('R=1,10', d) == ('R', [[1.0], [10.0]])
    assert sweep_tasks.parse_setting('R=1 0 0 1', d) == ('R', [[1.0, 0.0, 0.0, 1.0]])
    assert sweep_tasks.parse_setting('transition=euler,exact', d) == (
        'transition', ['euler', 'exact'])
    assert sweep_tasks.parse_setting('gate_patience=3', d) == ('gate_patience', [3])
    assert sweep_tasks.parse_setting('nonpositive_is_gap=false', d) == (
        'nonpositive_is_gap', [False])
    for bad in ('R', 'nothing=1', 'R=x', 'R=1,,2', 'gate=a', 'queue_depth=3'):
        with pytest.raises(ValueError):
            sweep_tasks.parse_setting(bad, d)


def test_two_workers_give_the_sequential_rows_and_a_damaged_bag_is_reported(bags, tmp_path):
    found = sweep_tasks.find_bags([str(bags)])
    seq = sweep.sweep(found, out=tmp_path / 'seq.csv', params_file=PARAMS, sets=SETS,
                      workers=0)
    par = sweep.sweep(found, out=tmp_path / 'par.csv', params_file=PARAMS, sets=SETS,
                      workers=2)
    assert len(seq.rows) == len(par.rows) == 16 and len(seq.evaluated) == 16
    a, b = rows_by_key(seq.rows), rows_by_key(par.rows)
    assert_same(a, b)
    with open(tmp_path / 'par.csv', newline='') as f:
        on_disk = list(csv.DictReader(f))
    assert_same(rows_by_key(on_disk), b)
    for (bag, R, transition), row in a.items():
        name = Path(bag).name
        if name == 'damaged':
            assert row['error'].startswith('damaged:') and 'byte' in row['error']
            assert int(row['n_messages']) < 288   # what came before the damage
        elif name == 'drogue':
            # a bag of another model (inputs, truth of other states): an error row
            assert 'another model' in row['error'] and row['n_messages'] == ''
        else:
            assert row['error'] == '', row['error']
        if name in ('a', 'b'):
            assert int(row['n_messages']) == 288 and int(row['gaps']) == 5
            # the last sample's corrected estimate waits for its mu
            assert row['truth_topic'] == '/true_angle' and int(row['truth_points']) == 287
            assert 0 < float(row['rms_corrected']) < 0.1
            assert float(row['nis_band_lo']) < 1 < float(row['nis_band_hi'])
    assert seq.errors == par.errors == 8
    # the copies of one bag give the same numbers under each setting
    for R in ('1.0', '100.0'):
        for tr in ('euler', 'exact'):
            ra = a[(str(bags / 'terminal' / 'a'), R, tr)]
            rb = a[(str(bags / 'terminal' / 'b'), R, tr)]
            assert ra['rms_corrected'] == rb['rms_corrected'] and ra['key'] != rb['key']
    assert set(METRICS) <= set(on_disk[0])


def test_resume_skips_finished_rows(bags, tmp_path):
    found = sweep_tasks.find_bags([str(bags / 'terminal' / '[ab]')])
    out = tmp_path / 'table.csv'
    full = sweep.sweep(found, out=out, params_file=PARAMS, sets=SETS, workers=0)
    assert len(full.evaluated) == 8 and not full.skipped
    lines = out.read_text().splitlines(keepends=True)
    # an interrupted run: the header, three finished rows and half of a fourth
    out.write_text(''.join(lines[:4]) + lines[4][:30])
    done = [line.split(',')[0] for line in lines[1:4]]
    again = sweep.sweep(found, out=out, params_file=PARAMS, sets=SETS, workers=0)
    assert sorted(again.skipped) == sorted(done)
    assert len(again.evaluated) == 5 and not set(again.evaluated) & set(done)
    assert_same({r['key']: r for r in again.rows}, {r['key']: r for r in full.rows})
    keys = [line.split(',')[0] for line in out.read_text().splitlines()[1:]]
    assert sorted(keys) == sorted(r['key'] for r in full.rows)
    # nothing left to do; --no-resume starts again
    assert sweep.sweep(found, out=out, params_file=PARAMS, sets=SETS,
                       workers=0).evaluated == []
    assert len(sweep.sweep(found, out=out, params_file=PARAMS, sets=SETS[:1], workers=0,
                           resume=False).evaluated) == 4
    # a touched bag is a new key: evaluated again
    (found[0] + '/metadata.yaml') and Path(found[0], 'metadata.yaml').touch()
    again = sweep.sweep(found, out=out, params_file=PARAMS, sets=SETS[:1], workers=0)
    assert len(again.evaluated) == 2


def test_cli_writes_the_table_and_the_figure(bags, tmp_path, capsys):
    out, png = tmp_path / 't.csv', tmp_path / 's.png'
    rc = sweep.main(['--bags', str(bags / 'terminal' / 'a'), '--params-file', str(PARAMS),
                     '--set', 'R=1,100', '--workers', '0', '--out', str(out), '--png',
                     str(png), '--fit', '--no-progress'])
    assert rc == 0, capsys.readouterr().err
    rows = list(csv.DictReader(open(out, newline='')))
    assert len(rows) == 2 and png.stat().st_size > 1000
    assert all(r['fit_error'] == '' and float(r['fit_log_likelihood']) < 0 for r in rows)
    # the fit starts from the setting's R but finds the same maximum
    assert float(rows[0]['fit_log_likelihood']) == pytest.approx(
        float(rows[1]['fit_log_likelihood']), rel=1e-6)
    assert 'evaluated' in capsys.readouterr().out
    for argv, text in ((['--set', 'nothing=1'], 'not a parameter'),
                       (['--set', 'R=1', '--set', 'R=2'], 'twice'),
                       (['--set', 'R=1 2'], 'R must have')):
        rc = sweep.main(['--bags', str(bags / 'terminal' / 'a'), '--params-file', str(PARAMS),
                         '--workers', '0', '--out', str(tmp_path / 'x.csv')] + argv)
        err = capsys.readouterr().err
        assert rc == 1 and text in err and len(err.strip().splitlines()) == 1, err
    rc = sweep.main(['--bags', str(tmp_path / 'none*'), '--out', str(tmp_path / 'y.csv')])
    assert rc == 1 and 'no bags' in capsys.readouterr().err


def test_ctrl_c_keeps_the_finished_rows_in_one_line_and_resumes(
        bags, tmp_path, capsys, monkeypatch):
    out = tmp_path / 'c.csv'
    argv = ['--bags', str(bags / 'terminal' / '[ab]'), '--params-file', str(PARAMS),
            '--set', 'R=1,100', '--workers', '0', '--out', str(out), '--no-progress']
    real, calls = sweep.run_task, []

    def interrupted_third(task, progress=None):
        calls.append(task.key)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(task, progress)

    monkeypatch.setattr(sweep, 'run_task', interrupted_third)
    assert sweep.main(argv) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'interrupted' in err[0] and '2 rows' in err[0], err
    assert len(list(csv.DictReader(open(out, newline='')))) == 2
    monkeypatch.setattr(sweep, 'run_task', real)
    assert sweep.main(argv) == 0
    assert '2 evaluated, 2 already in' in capsys.readouterr().out
    assert len(list(csv.DictReader(open(out, newline='')))) == 4


def test_a_second_sweep_on_the_same_table_is_refused(bags, tmp_path, capsys):
    out = tmp_path / 't.csv'
    argv = ['--bags', str(bags / 'terminal' / 'a'), '--params-file', str(PARAMS),
            '--workers', '0', '--out', str(out), '--no-progress']
    assert sweep.main(argv) == 0
    before = out.read_bytes()
    running = sweep_table.Table(out, before.decode().splitlines()[0].split(','), resume=True)
    try:
        for extra in ([], ['--no-resume'], ['--set', 'R=5']):
            assert sweep.main(argv + extra) == 1
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and 'another sweep is writing' in err[0], err
            assert out.read_bytes() == before
    finally:
        running.close()
    assert sweep.main(argv + ['--no-resume']) == 0
    assert len(list(csv.DictReader(open(out, newline='')))) == 1


def test_an_existing_scheduler_runs_the_same_sweep(bags, tmp_path):
    # --scheduler: the sweep submits to a cluster it did not start, and leaves it running
    from dask.distributed import LocalCluster
    found = sweep_tasks.find_bags([str(bags / 'terminal' / 'a')])
    seq = sweep.sweep(found, out=tmp_path / 'seq.csv', params_file=PARAMS, sets=SETS[:1],
                      workers=0)
    with LocalCluster(n_workers=1, threads_per_worker=1, host='127.0.0.1',
                      dashboard_address=None) as cluster:
        remote = sweep.sweep(found, out=tmp_path / 'remote.csv', params_file=PARAMS,
                             sets=SETS[:1], scheduler=cluster.scheduler_address)
        assert len(cluster.scheduler.workers) == 1
    assert len(remote.evaluated) == 2
    assert_same({r['key']: r for r in seq.rows}, {r['key']: r for r in remote.rows})


@pytest.mark.parametrize('workers', [0, 2])
def test_a_bag_by_path_and_by_symlink_is_one_row(bags, tmp_path, workers):
    real = bags / 'terminal' / 'a'
    (tmp_path / 'link').symlink_to(real)
    found = sweep_tasks.find_bags([str(real), str(tmp_path / 'link')])
    assert found == [str(real)]
    # given to sweep() directly, both spellings still make one task and one row
    res = sweep.sweep([str(tmp_path / 'link'), str(real)], out=tmp_path / 't.csv',
                      params_file=PARAMS, sets=SETS[:1], workers=workers)
    assert len(res.evaluated) == len(res.rows) == 2
    assert len({r['key'] for r in res.rows}) == 2
    assert all(int(r['n_messages']) == 288 for r in res.rows)


def test_the_node_ranges_refuse_a_setting_in_one_line(bags, tmp_path, capsys):
    base = ['--bags', str(bags / 'terminal' / 'a'), '--params-file', str(PARAMS),
            '--workers', '0', '--out', str(tmp_path / 't.csv'), '--no-progress']
    for setting, name in (('period=1e-300', 'period'), ('jump_factor=0', 'jump_factor'),
                          ('dense_fraction=7', 'dense_fraction'),
                          ('max_jump=1e308', 'max_jump'), ('gate=nan', 'gate'),
                          ('period=inf', 'period')):
        assert sweep.main(base + ['--set', setting]) == 1
        one_line(capsys.readouterr().err, '', name)      # out of range, or not finite: named
    assert not (tmp_path / 't.csv').exists()


def test_settings_are_typed_with_the_right_words():
    d = default_parameters()
    assert sweep_tasks.parse_setting('history_size=1e3', d) == ('history_size', [1000])
    assert sweep_tasks.parse_setting('state_names=a', d) == ('state_names', [['a']])
    with pytest.raises(ValueError, match='not an integer'):
        sweep_tasks.parse_setting('history_size=2.5', d)


def test_no_output_may_be_a_file_of_an_input_bag(bags, tmp_path, capsys):
    a = tmp_path / 'a'
    shutil.copytree(bags / 'terminal' / 'a', a)
    before = {p.name: p.read_bytes() for p in a.iterdir()}
    for extra in (['--out', str(a / 'owc_cai_td_1hz.mcap')],
                  ['--out', str(tmp_path / 't.csv'), '--png', str(a / 'metadata.yaml')],
                  ['--out', str(a / 'new.csv')]):
        assert sweep.main(['--bags', str(a), '--workers', '0', '--no-progress',
                           '--params-file', str(PARAMS)] + extra) == 1
        one_line(capsys.readouterr().err, '', 'input bag')
        assert {p.name: p.read_bytes() for p in a.iterdir()} == before


def test_bags_of_other_models_are_error_rows(tmp_path):
    found = [str(REPO / 'bags' / n) for n in ('owc_cai_td_1hz', 'led_alignment', 'drogue')]
    res = sweep.sweep(found, out=tmp_path / 't.csv', params_file=PARAMS, workers=0)
    rows = {Path(r['bag']).name: r for r in res.rows}
    assert rows['owc_cai_td_1hz']['error'] == ''
    for name, why in (('led_alignment', '/alignment/truth'), ('drogue', '/input')):
        assert 'another model' in rows[name]['error'] and why in rows[name]['error']
        assert rows[name]['nis_mean'] == ''


def test_the_figure_says_which_dot_is_which_bag(bags, tmp_path, monkeypatch):
    found = sweep_tasks.find_bags([str(bags)])
    res = sweep.sweep(found, out=tmp_path / 't.csv', params_file=PARAMS, sets=SETS[:1],
                      workers=0)
    figures = []
    monkeypatch.setattr(sweep, 'save_figure', lambda fig, path: figures.append(fig) or path)
    sweep.plot(res.rows, SETS[:1], tmp_path / 's.png')
    fig = figures[0]
    axes = fig.axes
    # no gated sample in any row: no panel of zeros, a note instead
    assert len(axes) == 2
    notes = ' '.join(t.get_text() for t in fig.texts)
    assert 'no sample was rejected by the innovation gate' in notes
    assert 'damaged' in notes and 'drogue' in notes       # the error rows, named
    legend = [t.get_text() for t in axes[0].get_legend().get_texts()]
    assert legend == ['a', 'b']
    assert [t.get_text() for t in axes[1].get_legend().get_texts()] == [
        '95% band of the mean NIS']
    # the band: one bar per drawn row, from nis_band_lo to nis_band_hi
    bands = [c for c in axes[1].collections if c.get_label().startswith('95%')]
    segments = [s for c in axes[1].collections for s in c.get_segments()]
    good = [r for r in res.rows if not r['error']]
    assert bands and len(segments) == len(good)
    assert sorted(round(s[0][1], 9) for s in segments) == sorted(
        round(float(r['nis_band_lo']), 9) for r in good)
    for ax in axes:
        assert ax.get_yscale() == 'log' and ax.get_ylabel()
        fig.canvas.draw()
        lo, hi = ax.get_ylim()
        shown = [t for t in ax.get_yticklabels() if t.get_text() and lo <= t.get_position()[1]
                 <= hi]
        assert len(shown) >= 3, [t.get_text() for t in shown]


def test_a_busy_port_8787_gives_no_warning():
    # another sweep (or any dask cluster) holds 8787: the scheduler's HTTP server takes a
    # loopback port of its own instead of warning on stderr
    holder = socket.socket()
    try:
        holder.bind(('0.0.0.0', 8787))
        holder.listen()
    except OSError:
        pass                                    # already held by someone else: as wanted
    try:
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter('always')
            cluster = sweep.local_cluster(1)
            cluster.close()
        assert not [w for w in seen if 'already in use' in str(w.message)]
    finally:
        holder.close()


def test_quiet_dask_silences_the_loggers_distributed_gives_levels_of_their_own():
    # distributed's config sets tornado.application to ERROR itself: after a Ctrl-C its
    # sync() cancel callback logs there, so the parent's level is not enough
    cluster = sweep.local_cluster(1)
    try:
        sweep.quiet_dask()
        loud = [name for name, logger in logging.root.manager.loggerDict.items()
                if isinstance(logger, logging.Logger)
                and name.split('.')[0] in ('distributed', 'tornado', 'asyncio')
                and logger.isEnabledFor(logging.CRITICAL)]
        assert loud == []
    finally:
        cluster.close()
