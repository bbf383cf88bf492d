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

"""The papers' numerical examples: what Cai et al. report, checked on fixed seeds."""

import json

import numpy as np
import pytest

from tskf_ros.core import linear_models as models, time_scales as timescale
from tskf_ros.experiments import reproduce

SEED = 2013     # the README's seed (reproduce's default)


@pytest.fixture(scope='module')
def td_runs():
    """Cai T_d with dense parts every 0.1 s, the three systems as `reproduce` runs them."""
    td = timescale.cai_td(0.1)
    runs = {}
    for i, system in enumerate(('owc', 'owc_random_walk', 'reference')):
        series = reproduce.run_cai_td(system, td, np.random.default_rng([SEED, 100 + i]),
                                      noise_scaling='theory')
        runs[system] = (series, reproduce.td_summary(series))
    return runs


def test_cai_td_owc_largest_errors_are_right_after_the_jumps():
    td = timescale.cai_td(0.1)
    res = reproduce.td_summary(
        reproduce.run_cai_td('owc', td, np.random.default_rng(7), noise_scaling='theory'))
    e = res['euler']
    post = [p['t'] for p in e['post_jump_points']]
    assert post == [32.0, 128.0, 135.0, 212.0, 224.0]
    # the five worst predictor errors are exactly the five post-jump points ...
    assert sorted(w['t'] for w in e['worst_points']) == post
    # ... the largest after the longest jump (J = 6), and they grow with J
    errs = {p['J']: abs(p['estimation_error']) for p in e['post_jump_points']}
    assert e['worst_points'][0]['t'] == 224.0
    assert errs[6.0] > errs[4.0] > errs[3.0] > max(errs[2.0], 0.5)
    # the corrected estimate removes most of it: ~0.05 rad against ~2 rad
    assert e['post_jump_mean_abs_error']['ratio_corrected_to_predictor'] < 0.1
    assert e['rms_corrected_error'] < 0.5 * e['rms_estimation_error']


def test_example_320_errors_are_bounded_on_all_four_time_scales():
    for i, name in enumerate(reproduce.EXAMPLE_320_SCALES):
        s = reproduce.run_example_320(name, 150, np.random.default_rng([3, i]),
                                      noise_scaling='theory', p12_step=0.25)
        m = reproduce.metrics(s)
        # filter covariance stays bounded, and errors stay within 4 predicted sigmas
        assert np.all(np.isfinite(s.pred)) and np.max(s.sd_pred) < 10
        assert np.mean(np.abs(s.pred - s.truth) < 4 * s.sd_pred) > 0.97
        assert m['max_abs_estimation_error'] < 12


def test_example_320_on_2z_estimation_error_exceeds_measurement_error():
    # Cai Section III-B: on T_1 = 2Z 'the estimation error is a bit larger than the
    # measurement error'; on {H_n} it is 'much smaller'.
    rms2z, rmshn = [], []
    for seed in range(5):
        a = reproduce.metrics(reproduce.run_example_320(
            '2Z', 150, np.random.default_rng(seed), noise_scaling='theory', p12_step=0.25))
        b = reproduce.metrics(reproduce.run_example_320(
            'H_n', 150, np.random.default_rng(seed), noise_scaling='theory', p12_step=0.25))
        rms2z.append(a['rms_estimation_error'] / a['rms_measurement_error'])
        rmshn.append(b['rms_estimation_error'] / b['rms_measurement_error'])
    assert min(rms2z) > 1.5
    assert max(rmshn) < 0.2


@pytest.mark.slow
def test_command_writes_whole_json_and_pngs(tmp_path, capsys):
    rc = reproduce.main(['--out', str(tmp_path), '--iterations', '6', '--long-iterations',
                         '12', '--td-dense-step', '0.5'])
    assert rc == 0
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert set(summary['example_3_20']) == set(reproduce.EXAMPLE_320_SCALES)
    assert [p['J'] for p in summary['cai_td']['owc']['euler']['post_jump_points']] == \
        [2.0, 2.0, 4.0, 3.0, 6.0]
    pngs = sorted(p.name for p in tmp_path.glob('*.png'))
    assert len(pngs) == 4 * 2 + 3
    assert all((tmp_path / p).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' for p in pngs)
    assert not list(tmp_path.glob('.*.part'))
    out = capsys.readouterr().out
    assert out.count('[example 3.20]') == 8 and out.count('[cai T_d]') == 3
    # the numbers written are those of the seeded runs the README describes (seed 2013:
    # [seed, scale index, points] for Example 3.20, [seed, 100 + system index] for T_d)
    assert summary['seed'] == SEED and summary['noise_scaling'] == 'theory'
    for i, name in enumerate(reproduce.EXAMPLE_320_SCALES):
        for label, count in (('paper', 6), ('long', 12)):
            m = reproduce.metrics(reproduce.run_example_320(
                name, count, np.random.default_rng([SEED, i, count]), noise_scaling='theory',
                p12_step=0.25))
            got = summary['example_3_20'][name][label]
            for key in ('rms_estimation_error', 'rms_corrected_error', 'rms_measurement_error'):
                assert got[key] == pytest.approx(m[key], rel=1e-12)
            line = f'{name:12s} {count:4d} points: RMS estimation error '
            assert line + f"{m['rms_estimation_error']:.3f}" in out
    td = timescale.cai_td(0.5)
    res = reproduce.td_summary(reproduce.run_cai_td(
        'owc', td, np.random.default_rng([SEED, 100]), noise_scaling='theory'))
    got = summary['cai_td']['owc']
    for transition in ('euler', 'exact'):
        assert got[transition]['rms_estimation_error'] == pytest.approx(
            res[transition]['rms_estimation_error'], rel=1e-12)
    # with dense parts every 0.5 s the OWC post-jump errors still dominate
    assert sorted(w['t'] for w in got['euler']['worst_points']) == \
        [32.0, 128.0, 135.0, 212.0, 224.0]


# ---------------------------------------------------------------------------------------
# The README's numbers (seed 2013), each to its printed precision
# ---------------------------------------------------------------------------------------

# Example 3.20: (points, RMS estimation, RMS corrected, RMS measurement, max abs estimation)
EXAMPLE_320_README = {
    ('2Z', 15): (2.964, 1.165, 1.183, 8.03), ('2Z', 150): (3.227, 0.998, 1.035, 8.21),
    ('H_n', 15): (0.958, 0.812, 4.433, 2.70),        # README prints 2.71; it is 2.7046
    ('H_n', 150): (0.491, 0.468, 11.915, 2.07),
    ('P_1,2', 15): (1.567, 1.575, 3.792, 3.60), ('P_1,2', 150): (0.919, 0.830, 2.521, 3.26),
    ('2Z_then_H_n', 15): (1.851, 1.145, 45.872, 4.17),
    ('2Z_then_H_n', 150): (1.891, 1.851, 57.626, 3.69),
}
HALF = 0.5 * 1.001       # half a printed unit (the README rounds), with a hair of slack


@pytest.mark.parametrize('name, count', sorted(EXAMPLE_320_README))
def test_example_320_readme_table(name, count):
    i = reproduce.EXAMPLE_320_SCALES.index(name)
    s = reproduce.run_example_320(name, count, np.random.default_rng([SEED, i, count]),
                                  noise_scaling='theory', p12_step=0.25)
    m = reproduce.metrics(s)
    est, corr, meas, worst = EXAMPLE_320_README[(name, count)]
    assert m['points'] == count
    assert m['rms_estimation_error'] == pytest.approx(est, abs=HALF * 1e-3)
    assert m['rms_corrected_error'] == pytest.approx(corr, abs=HALF * 1e-3)
    assert m['rms_measurement_error'] == pytest.approx(meas, abs=HALF * 1e-3)
    assert m['max_abs_estimation_error'] == pytest.approx(worst, abs=HALF * 1e-2)


# Cai T_d: post-jump (predictor, corrected) errors, RMS all (pred, corr), worst 5 points
TD_README = {
    'owc': ([(1.066, 0.032), (1.060, -0.089), (2.512, -0.019), (1.689, 0.005),
             (3.264, -0.022)], (0.179, 0.047), [224.0, 135.0, 212.0, 32.0, 128.0]),
    'owc_random_walk': ([(0.032, 0.071), (0.064, -0.063), (0.001, 0.014), (0.045, 0.026),
                         (0.034, 0.012)], (0.048, 0.046), None),
    'reference': ([(1.178, 0.585), (-1.531, -1.176), (2.645, 1.304), (2.869, 2.256),
                   (-0.794, -0.312)], (0.599, 0.568), [225.0, 136.0, 212.0, 135.0, 237.0]),
}


@pytest.mark.parametrize('system', sorted(TD_README))
def test_cai_td_readme_table(td_runs, system):
    _, res = td_runs[system]
    e = res['euler']
    post, (rms_pred, rms_corr), worst = TD_README[system]
    assert [(p['t'], p['J']) for p in e['post_jump_points']] == [
        (32.0, 2.0), (128.0, 2.0), (135.0, 4.0), (212.0, 3.0), (224.0, 6.0)]
    got = [(p['estimation_error'], p['corrected_error']) for p in e['post_jump_points']]
    np.testing.assert_allclose(got, post, rtol=0, atol=HALF * 1e-3)
    assert e['rms_estimation_error'] == pytest.approx(rms_pred, abs=HALF * 1e-3)
    assert e['rms_corrected_error'] == pytest.approx(rms_corr, abs=HALF * 1e-3)
    worst_seen = [w['t'] for w in e['worst_points']]
    if worst is None:       # a = 0: the worst points are elsewhere
        assert not set(worst_seen) & {32.0, 128.0, 135.0, 212.0, 224.0}
    else:
        assert worst_seen == worst


def test_cai_td_readme_post_jump_and_exact_transition(td_runs):
    owc = td_runs['owc'][1]
    pj = owc['euler']['post_jump_mean_abs_error']
    # 'brings the mean absolute post-jump error from 1.92 rad to 0.033 rad (ratio 0.017)'
    assert pj['predictor'] == pytest.approx(1.92, abs=HALF * 1e-2)
    assert pj['corrected'] == pytest.approx(0.033, abs=HALF * 1e-3)
    assert pj['ratio_corrected_to_predictor'] == pytest.approx(0.017, abs=HALF * 1e-3)
    ref = td_runs['reference'][1]
    assert ref['euler']['post_jump_mean_abs_error']['ratio_corrected_to_predictor'] == \
        pytest.approx(0.62, abs=HALF * 1e-2)
    # 'OWC RMS 0.179 rad (euler) vs 4.89 rad (exact) ... reference system 0.599 vs 0.631 ft'
    assert owc['exact']['rms_estimation_error'] == pytest.approx(4.89, abs=HALF * 1e-2)
    assert ref['exact']['rms_estimation_error'] == pytest.approx(0.631, abs=HALF * 1e-3)


def test_cai_td_measurement_noise_is_r_over_mu(td_runs):
    # 'theory' scaling: a measurement at a point of graininess mu has variance R / mu
    # (R = 100 mW^2), so 10 R on the dense parts realised at 0.1 s, R at the 1 s points.
    # The measurement error in power units is slope * (measured - truth).
    for system in ('owc', 'owc_random_walk'):
        s = td_runs[system][0]['euler']
        v = models.OWC_SLOPE * (s.measured - s.truth)
        mu = s.mu[:-1]
        for m, want_sd in ((0.1, np.sqrt(1000.0)), (1.0, 10.0)):
            sel = v[:-1][np.isclose(mu, m)]
            assert sel.size > 40
            # the sample sd of n normals is within 4 sd / sqrt(2 n) of the true one
            assert np.std(sel) == pytest.approx(want_sd, abs=4 * want_sd / np.sqrt(2 * sel.size))


def test_simulate_truth_noise_scales_with_mu():
    # x(sigma) = (I + mu A) x + sqrt(mu) G w and v ~ N(0, R / mu) ('theory'); 'unit' draws
    # N(0, Q), N(0, R) whatever mu.  A = 0 makes the increments the noise itself.
    model = models.LinearModel('walk', A=np.zeros((1, 1)), C=np.ones((1, 1)), Q=np.eye(1),
                               R=4.0 * np.eye(1), x0=np.zeros(1), P0=np.eye(1))
    ts = timescale.h_integers(0.25, 20001)
    n = len(ts) - 1
    for scaling, var_w, var_v in (('theory', 0.25, 16.0), ('unit', 0.25 ** 2, 4.0)):
        x, y = models.simulate_truth(model, ts, np.random.default_rng(3), noise_scaling=scaling)
        dx, v = np.diff(x[:, 0]), y[:, 0] - x[:, 0]
        assert np.var(dx) == pytest.approx(var_w, rel=4 * np.sqrt(2 / n))
        assert np.var(v) == pytest.approx(var_v, rel=4 * np.sqrt(2 / n))


def test_cai_td_owc_mu_one_points_carry_the_angle_as_error(td_runs):
    # README: 'Under a = 1 every mu = 1 point also has a 0.5 rad error (mu x)': the
    # predictor multiplies theta (~0.54 rad) by 1 + mu = 2
    s = td_runs['owc'][0]['euler']
    before = timescale.backward_graininess(s.t)
    one = np.isclose(before, 1.0)
    err = np.abs(s.pred - s.truth)[one]
    assert one.sum() == 96
    assert np.median(err) == pytest.approx(0.5, abs=0.06)
    assert np.median(err) == pytest.approx(np.median(s.truth[one]), abs=0.02)
    # on the dense parts (mu = 0.1) the same error is ten times smaller
    assert np.median(np.abs(s.pred - s.truth)[np.isclose(before, 0.1)]) < 0.1


def test_ou_angle_statistics():
    # README: the true angle is an Ornstein-Uhlenbeck process, mean 0.5435 rad, sd 0.04 rad,
    # 2 s time constant, clipped to the linear range [0.4141, 0.6729] of eq. (2)
    t = np.arange(0.0, 40000.0, 1.0)
    th = models.ou_angle(t, np.random.default_rng(1))
    n_eff = t.size * (1 - np.exp(-0.5)) / (1 + np.exp(-0.5))    # AR(1) with rho = e^-1/2
    assert th.mean() == pytest.approx(0.5435, abs=4 * 0.04 / np.sqrt(n_eff))
    assert th.std() == pytest.approx(0.04, rel=0.03)
    assert np.corrcoef(th[:-1], th[1:])[0, 1] == pytest.approx(np.exp(-0.5), abs=0.02)
    assert th.min() >= 0.4141 and th.max() <= 0.6729
