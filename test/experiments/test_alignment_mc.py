"""The LED alignment Monte Carlo experiment (tskf_ros.experiments.alignment_mc): its JSON."""

import json

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.experiments import alignment_mc


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
