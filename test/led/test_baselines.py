"""The baselines of Solanki et al. 2018 (Section V): hill-climbing, three-point averaging (26)."""

import pytest

from tskf_ros import led


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
