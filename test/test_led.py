"""LED alignment (Solanki et al. 2018): g, Jacobian (17), observability, EKF and baselines."""

import json

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.experiments import alignment_mc

RESPONSE = led.IncidenceResponse()


def test_zone_unit_puts_20_percent_at_15_degrees():
    r = RESPONSE
    assert r.units_per_degree == pytest.approx(17.697, abs=1e-3)
    mean = 0.5 * (r.g(15.0) + r.g(-15.0)) / r.peak
    assert mean == pytest.approx(0.2, abs=1e-9)
    assert r.g(r.peak_angle) == pytest.approx(r.peak)


def test_literal_unit_is_nearly_flat():
    r = led.IncidenceResponse(units_per_degree=led.LITERAL_UNITS_PER_DEGREE)
    assert np.all(r.g(np.array([-15.0, 15.0])) / r.peak > 0.98)
    assert np.all(r.g(np.array([-180.0, 180.0])) / r.peak > 0.35)


def test_bad_unit_is_rejected():
    with pytest.raises(led.AlignmentError, match='units_per_degree'):
        led.IncidenceResponse(units_per_degree=0.0)


def test_dg_matches_finite_differences():
    phi = np.linspace(-40.0, 40.0, 81)
    h = 1e-5
    numeric = (RESPONSE.g(phi + h) - RESPONSE.g(phi - h)) / (2 * h)
    np.testing.assert_allclose(RESPONSE.dg(phi), numeric, rtol=1e-6, atol=1e-9)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(4)
    ekf = led.ScanningEKF(runs=50)
    x = np.column_stack([rng.uniform(0.5, 4.0, 50), rng.uniform(-20.0, 20.0, 50)])
    shift = rng.uniform(-5.0, 5.0, 50)
    psi_prev = rng.choice(led.SCAN_ANGLES, 50)
    psi = 6.0
    C = ekf.jacobian(x, psi, shift, psi_prev)
    eps = 1e-6
    for j in range(2):
        dx = np.zeros(2)
        dx[j] = eps
        numeric = (ekf.h(x + dx, psi, shift, psi_prev)
                   - ekf.h(x - dx, psi, shift, psi_prev)) / (2 * eps)
        np.testing.assert_allclose(C[:, :, j], numeric, rtol=1e-5, atol=1e-8)


def test_scan_set_is_the_papers():
    assert len(led.SCAN_ANGLES) == 20
    assert max(led.SCAN_ANGLES) == 10.0 and min(led.SCAN_ANGLES) == -10.0
    steps = np.abs(np.diff(np.r_[led.SCAN_ANGLES, led.SCAN_ANGLES[0]]))
    assert np.all(steps == 2.0)


def test_observability_fails_at_one_over_91():
    assert led.min_gain() == pytest.approx(1.0 / 91.0)
    with pytest.raises(led.ObservabilityError, match=r'G > 0\.010989'):
        led.check_observability(1.0 / 91.0)
    with pytest.raises(led.ObservabilityError):
        led.ScanningEKF(led.EKFConfig(gain=1.0 / 91.0))


def test_observability_passes_at_paper_gain():
    led.check_observability(0.5)
    ekf = led.ScanningEKF(led.EKFConfig(gain=0.5), runs=3)
    ekf.step(0.0, [2.0, 2.5, 3.0])
    ekf.step(0.05, [2.2, 2.4, 2.9])
    assert np.all(np.abs(ekf.det) > 0.0) and not ekf.singular.any()


def test_step_interface_for_a_node():
    ekf = led.ScanningEKF()
    first = ekf.step(10.0, 2.5)
    assert first.shape == (1,) and np.isfinite(first).all()
    ekf.step(10.05, None)
    ekf.step(10.10, float('nan'))
    with pytest.raises(led.AlignmentError, match='stale stamp'):
        ekf.step(10.10, 2.0)


def test_gap_prediction_uses_the_stamps():
    a, b = led.ScanningEKF(), led.ScanningEKF()
    for ekf in (a, b):
        ekf.step(0.0, 2.0)
        ekf.step(0.05, 2.6)
    P_post = a.P.copy()
    applied = [a.u[0]]
    for k in (2, 3, 4):          # a: one call per missing sample
        a.step(0.05 * k, None)
        applied.append(a.u[0])
    b.step(0.20, None)           # b: a single call after the gap, mu = 3
    np.testing.assert_allclose(a.P_prior, P_post + 3.0 * a.Q)
    np.testing.assert_allclose(b.P_prior, P_post + 3.0 * b.Q)
    # the next measurement is paired with the last one, shifted by the control since
    assert a.since[0] == pytest.approx(sum(applied))
    assert not a.updated.any()


def test_three_point_eq26():
    tp = led.ThreePointAveraging(gamma=2.0)
    assert tp.step(0.0, 3.0)[0] == 2.0          # V3 at the origin, turn to +gamma
    assert tp.step(0.05, 2.0)[0] == -4.0        # V1 at +gamma, turn to -gamma
    turn = tp.step(0.10, 1.0)[0]                # V2 at -gamma, back to origin + gamma_p
    assert turn == pytest.approx(2.0 + 2.0 * (2.0 - 1.0) / (2.0 + 1.0 + 3.0))


def test_hill_climbing_reverses_when_intensity_drops():
    hc = led.HillClimbing(gamma=2.0)
    assert hc.step(0.0, 1.0)[0] == 2.0
    assert hc.step(0.05, 1.5)[0] == 2.0
    assert hc.step(0.10, 1.2)[0] == -2.0
    assert hc.step(0.15, None)[0] == 0.0


def tracking_mean(name, noise, *, runs=200, beta=1.2, seed=0):
    aligner = led.make_aligner(name, runs=runs)
    traj = led.simulate_tracking(aligner, led.TrackingLinkConfig(beta=beta, noise=noise),
                                 np.random.default_rng(seed))
    angular, measure = led.tracking(traj)
    return float(np.mean(angular)), float(np.mean(measure))


def test_ekf_tracks_at_noise_one():
    # 12 seeds of 200 runs gave 98.1 +- 0.8 (angular); a 1000-run sweep gives ~97.5
    angular, measure = tracking_mean('ekf', 1.0)
    assert angular == pytest.approx(98.1, abs=2.5)
    assert measure == pytest.approx(angular, abs=2.0)


def test_ordering_at_high_noise():
    # noise 2.0 V, 12 seeds of 200 runs: EKF 84.3 +- 2.5, hill 73.2 +- 2.2, 3-point 63.0 +- 1.9
    ekf = tracking_mean('ekf', 2.0)[0]
    hill = tracking_mean('hill_climbing', 2.0)[0]
    three = tracking_mean('three_point', 2.0)[0]
    assert ekf > hill + 3.0 > three + 6.0


def test_large_beta_fails():
    angular, _ = tracking_mean('ekf', 0.2, runs=50, beta=alignment_mc.FAIL_BETA)
    assert angular < 30.0


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
    assert 'noise' in capsys.readouterr().out
