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

"""The LED alignment Monte Carlo experiment (tskf_ros.experiments.alignment_mc): its JSON."""

import dataclasses
import json

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.experiments import alignment_mc, alignment_pat


def test_experiment_writes_the_schema(tmp_path, capsys):
    out = tmp_path / 'a.json'
    rc = alignment_mc.main(['--runs', '4', '--steps', '30', '--noise-levels', '0.5,1.5',
                            '--json', str(out)])
    assert rc == 0
    data = json.loads(out.read_text())
    assert data['noise_levels'] == [0.5, 1.5]
    for name in led.ALGORITHMS:
        for metric in ('angular', 'measure'):
            assert len(data['results'][name][metric]['mean']) == 2
            assert len(data['results'][name][metric]['std']) == 2
    # the numbers: each algorithm in closed loop, 4 runs of 30 steps, seed 0 at each level
    for i, noise in enumerate((0.5, 1.5)):
        link = led.TrackingLinkConfig(beta=1.2, steps=30, noise=noise)
        for name in led.ALGORITHMS:
            traj = led.simulate_tracking(led.make_aligner(name, runs=4), link,
                                         np.random.default_rng(0))
            angular, measure = led.tracking(traj)
            got = data['results'][name]
            assert got['angular']['mean'][i] == pytest.approx(np.mean(angular), abs=1e-12)
            assert got['angular']['std'][i] == pytest.approx(np.std(angular), abs=1e-12)
            assert got['measure']['mean'][i] == pytest.approx(np.mean(measure), abs=1e-12)
            # by angle: the share of the 30 steps with |phi| <= 15 deg, from the trajectory
            inside = np.mean(np.abs((traj.phi + 180.0) % 360.0 - 180.0) <= 15.0, axis=0)
            assert got['angular']['mean'][i] == pytest.approx(100 * np.mean(inside), abs=1e-9)
    assert 'noise' in capsys.readouterr().out


def test_alignment_mc_records_the_controller(tmp_path, capsys):
    out = tmp_path / 'a.json'
    assert alignment_mc.main(['--runs', '3', '--steps', '30', '--noise-levels', '0.2',
                              '--controller', 'lqg', '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert data['config']['controller'] == 'lqg'
    assert set(data['results']) == set(led.ALGORITHMS)


def test_supervised_algorithms_write_the_lock_fields(tmp_path, capsys):
    out = tmp_path / 'a.json'
    names = ('ekf',) + alignment_mc.PAT_ALGORITHMS
    assert alignment_mc.main(['--runs', '6', '--steps', '60', '--noise-levels', '1.0',
                              '--algorithms', ','.join(names), '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert set(data['results']) == set(names)
    for name in names:
        got = data['results'][name]
        assert len(got['lost_at_end']) == 1 and 0.0 <= got['lost_at_end'][0] <= 1.0
        events = {'median', 'p90', 'events', 'ended', 'censored'}
        assert set(got['reacquisition_s']) == events
        assert set(got['supervisor_latency_s']) == events
        assert set(got['acquisition_s']) == events | {'mean_ended', 'histogram'}
    # the plain algorithms declare nothing: no false-alarm rate
    assert data['results']['ekf']['false_alarms_per_1000s'] == [None]
    assert data['results']['ekf_pat']['false_alarms_per_1000s'][0] is not None
    assert 'ekf_pat' in capsys.readouterr().out


@pytest.mark.parametrize('noise', ['0', '1.0'])
def test_a_blocked_beam_is_lost_by_every_run_and_recorded(noise, tmp_path, capsys):
    # 3 s without light in every run: each ekf_pat run declares the loss once and tracks
    # again after the block; the block is in the JSON's config
    out = tmp_path / 'a.json'
    assert alignment_mc.main(['--runs', '5', '--steps', '300', '--noise-levels', noise,
                              '--blocked', '5,8', '--algorithms', 'ekf_pat',
                              '--json', str(out)]) == 0
    data = json.loads(out.read_text())
    assert data['config']['blocked_s'] == [5.0, 8.0]
    got = data['results']['ekf_pat']
    assert got['supervisor_latency_s']['events'] == [5]
    # the lock-window latency: declared within the block (12 of 20 dark samples: 0.6 s),
    # tracking after it
    assert 8.0 - 5.0 - 0.6 < got['supervisor_latency_s']['median'][0] < 8.0 - 5.0 + 2.0
    # the pointing, from the light's return: at most one event per run, back within 2 s
    reacq = got['reacquisition_s']
    assert reacq['events'][0] <= 5 and reacq['censored'] == [0]
    assert reacq['events'][0] == 0 or 0.0 <= reacq['median'][0] <= 2.0
    assert got['lost_at_end'] == [0.0]


@pytest.mark.parametrize('blocked', ['50,60', '20,21'])
def test_a_blocked_interval_outside_the_run_is_refused(blocked, capsys):
    # 400 steps of 0.05 s: the run is 0 to 20 s; a block from 20 s on never happens
    with pytest.raises(SystemExit) as info:
        alignment_mc.main(['--runs', '2', '--steps', '400', '--dt', '0.05',
                           '--blocked', blocked])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith(f'--blocked {blocked}: the blocked interval lies outside the run '
                        '(400 steps of 0.05 s: 0 to 20 s)'), err


@pytest.mark.parametrize('blocked', ['5', '8,5', '1,2,3'])
def test_a_blocked_interval_needs_start_before_stop(blocked, capsys):
    with pytest.raises(SystemExit) as exc:
        alignment_mc.main(['--runs', '2', '--blocked', blocked])
    assert exc.value.code == 2
    assert '--blocked needs START,STOP' in capsys.readouterr().err


def test_cold_start_histogram_figure(tmp_path, capsys):
    png, out = tmp_path / 'h.png', tmp_path / 'h.json'
    assert alignment_mc.main(['--runs', '6', '--steps', '120', '--noise-levels', '1.0',
                              '--cold-start', '90', '--algorithms', 'ekf,ekf_pat',
                              '--json', str(out), '--acquisition-png', str(png)]) == 0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    hist = json.loads(out.read_text())['results']['ekf_pat']['acquisition_s']['histogram'][0]
    assert sum(hist['counts']) + hist['censored'] == 6
    assert hist['edges_s'][0] == 0.0 and hist['edges_s'][-1] >= 6.0


def test_no_comparison_refuses_the_comparison_outputs(tmp_path, capsys):
    # --json and --png belong to the comparison: with --no-comparison they are refused in
    # one line, and nothing is written
    out = tmp_path / 'f.json'
    for flag in ('--json', '--png', '--acquisition-png'):
        with pytest.raises(SystemExit) as exc:
            alignment_mc.main(['--runs', '2', '--no-comparison', flag, str(out)])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert 'which --no-comparison skips' in err[-1]
    assert not out.exists()


def test_metrics_of_a_scripted_trajectory():
    # 2 runs, 6 steps of 0.5 s: run 0 leaves the zone at step 2 (declared lost there) and
    # is back, tracking, at step 4; run 1 never leaves and has one declared loss
    phi = np.array([[0, 0], [5, 1], [30, 2], [40, 3], [10, 4], [0, 5]], dtype=float)
    t = np.arange(6) * 0.5
    traj = led.Trajectory(t=t, phi=phi, x2=phi, x1=np.ones_like(phi), clean=np.ones_like(phi),
                          z=np.ones_like(phi), command=np.zeros_like(phi))
    T, L = 1, 2
    states = np.array([[T, T], [T, T], [L, T], [L, T], [T, T], [T, T]])
    declared = np.zeros((6, 2), dtype=bool)
    declared[2, 0] = declared[3, 1] = True
    m = alignment_pat.metrics(traj, states, declared)
    assert m['lost_at_end'] == 0.0
    # the supervisor's latency: run 0 lost at step 2, tracking in the zone at 4; run 1's
    # false alarm at 3 is 'tracking in the zone' at once (0 s)
    np.testing.assert_allclose(sorted(m['latency'].times), [0.0, 1.0])
    # the pointing: run 0 leaves the zone at step 2 and is back at 4 and stays (hold 1 s
    # = 2 steps): 1.0 s; run 1 never leaves
    np.testing.assert_allclose(m['reacquisition'].times, [1.0])
    # one declared loss in run 1's 3 s (6 steps of 0.5 s) never out of the zone
    assert m['false_alarms_per_1000s'] == pytest.approx(1000.0 / 3.0)
    np.testing.assert_allclose(m['acquisition'].times, [0.0, 0.0])


def test_workers_give_the_sequential_results_run_for_run():
    # each point starts its own generator from the seed: the same numbers on any workers
    link = led.TrackingLinkConfig(beta=1.2, steps=80)
    common = {'runs': 5, 'link': link, 'seed': 3, 'response': led.IncidenceResponse(),
              'ekf': led.EKFConfig(), 'algorithms': ('ekf', 'three_point', 'ekf_pat')}
    one = alignment_mc.sweep('noise', [0.5, 2.0], workers=1, **common)['results']
    two = alignment_mc.sweep('noise', [0.5, 2.0], workers=2, **common)['results']
    assert json.dumps(one, sort_keys=True) == json.dumps(two, sort_keys=True)
    points = [alignment_mc.Point(name, 5, dataclasses.replace(link, noise=1.5), 3,
                                 led.IncidenceResponse(), led.EKFConfig(), False, 'p')
              for name in ('ekf', 'hill_climbing_pat')]
    for (a1, m1, _), (a2, m2, _) in zip(alignment_mc.run_points(points, 1),
                                        alignment_mc.run_points(points, 2)):
        np.testing.assert_array_equal(a1, a2)
        np.testing.assert_array_equal(m1, m2)


def test_a_point_in_parts_is_the_same_on_any_workers_and_its_first_part_is_the_seeds():
    # 7 runs in parts of 3 (3, 3, 1): the parts are the tasks; joined in order they give
    # the same numbers on one process or two, and the first part draws what an
    # undivided point of 3 runs draws from the seed
    link = led.TrackingLinkConfig(beta=1.2, steps=60, noise=1.5)
    point = alignment_mc.Point('ekf_pat', 7, link, 4, led.IncidenceResponse(), led.EKFConfig(),
                               False, 'p')
    one = list(alignment_mc.run_points([point], 1, part_runs=3))[0]
    two = list(alignment_mc.run_points([point], 2, part_runs=3))[0]
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])
    assert repr(one[2]) == repr(two[2])
    assert one[0].shape == (7,) and one[2]['runs'] == 7
    first = alignment_mc.run_point(dataclasses.replace(point, runs=3))
    np.testing.assert_array_equal(one[0][:3], first[0])
    np.testing.assert_array_equal(one[1][:3], first[1])


@pytest.mark.parametrize('parameter, values, names, extra', [
    ('noise', (0.0, 1.25, 2.5), ('ekf', 'three_point', 'ekf_pat', 'hill_climbing_pat',
                                 'ekf_reset'), {}),
    ('dropout', (0.0, 0.3), ('ekf', 'ekf_hold', 'hill_climbing'), {'noise': 1.0}),
    ('noise', (0.5, 2.0), ('three_point_pat', 'ekf_pat'),
     {'x2_0': 0.0, 'x2_0_spread': 40.0, 'blocked': (2.0, 3.0)}),
])
def test_levels_and_parts_side_by_side_are_each_part_alone_run_for_run(parameter, values,
                                                                       names, extra):
    # the sequential path: one part (of at most 3 runs) at a time, each on its own
    # aligner; batched: every level and part of an algorithm side by side in one task (and
    # in tasks of 6 runs on two workers); the same numbers, run for run
    link = led.TrackingLinkConfig(beta=1.2, steps=80, **extra)
    points = [alignment_mc.Point(name, 7, dataclasses.replace(link, **{parameter: v}), 5,
                                 led.IncidenceResponse(), led.EKFConfig(), False, 'p')
              for v in values for name in names]
    alone = list(alignment_mc.run_points(points, 1, part_runs=3, batch_runs=3))
    for workers, batch in ((1, 10**6), (2, 6)):
        together = list(alignment_mc.run_points(points, workers, part_runs=3, batch_runs=batch))
        assert len(together) == len(points)
        for (a1, m1, k1), (a2, m2, k2) in zip(alone, together):
            np.testing.assert_array_equal(a1, a2)
            np.testing.assert_array_equal(m1, m2)
            assert repr(k1) == repr(k2)


def test_tasks_hold_one_kind_and_take_the_kinds_in_turn():
    link = led.TrackingLinkConfig()
    points = [alignment_mc.Point(name, 1000, dataclasses.replace(link, noise=v), 0,
                                 led.IncidenceResponse(), led.EKFConfig(), False, 'p')
              for v in (0.0, 0.5, 1.0) for name in ('ekf', 'ekf_pat')]
    # ekf at 0.0, 0.5 | ekf_pat at 0.0, 0.5 | ekf at 1.0 | ekf_pat at 1.0
    assert alignment_mc.batches(points, 2000) == [[0, 2], [1, 3], [4], [5]]
    # a point larger than a task is a task of its own
    assert alignment_mc.batches(points[:1], 10) == [[0]]


def test_the_metrics_of_parts_joined_are_the_metrics_of_all_runs():
    # one simulation of 6 runs cut into runs 0-3 and 4-5: metrics of each, joined, equal
    # the metrics of the whole (the same events, counts over all runs)
    link = led.TrackingLinkConfig(beta=1.2, steps=200, noise=2.5, blocked=(4.0, 5.0))
    *_, traj, rec = alignment_pat.evaluate('ekf_pat', 6, link, np.random.default_rng(2),
                                           led.IncidenceResponse(), led.EKFConfig(), False)
    states, declared = np.array(rec.states), np.array(rec.declared)

    def cut(runs):
        part = led.Trajectory(t=traj.t, **{f: getattr(traj, f)[:, runs] for f in
                                           ('phi', 'x2', 'x1', 'clean', 'z', 'command')})
        return alignment_pat.metrics(part, states[:, runs], declared[:, runs],
                                     blocked=link.blocked)

    whole = alignment_pat.metrics(traj, states, declared, blocked=link.blocked)
    joined = alignment_pat.join_metrics([cut(slice(0, 4)), cut(slice(4, 6))])
    assert whole.keys() == joined.keys()
    for key, value in whole.items():
        if isinstance(value, alignment_pat.pointing_metrics.Durations):
            # the same events (the latency's are listed by step, not by run: sorted)
            assert sorted(zip(value.times, value.observed)) == sorted(
                zip(joined[key].times, joined[key].observed)), key
        else:
            assert value == joined[key], key
