"""The papers' numerical examples: what Cai et al. report, checked on fixed seeds."""

import json

import numpy as np

from tskf_ros.core import time_scales as timescale
from tskf_ros.experiments import reproduce


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
