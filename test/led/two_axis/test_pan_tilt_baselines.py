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

"""The two-axis baselines: hill climbing with the axes alternating, four-point averaging."""

import math

import numpy as np
import pytest

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.two_axis.pan_tilt_baselines import FourPointAveraging, TwoAxisHillClimbing
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt


def hill_by_hand(zs, gamma):
    """One run of hill climbing, written out: return its turns [(c, e), ...]."""
    direction = [1.0, 1.0]
    reference = None
    axis, moved = 0, None
    turns = []
    for z in zs:
        if z is None or math.isnan(z):
            turns.append((0.0, 0.0))
            continue
        if reference is not None and moved is not None and not z > reference:
            direction[moved] = -direction[moved]
        reference = z
        turn = [0.0, 0.0]
        turn[axis] = gamma * direction[axis]
        turns.append(tuple(turn))
        moved, axis = axis, 1 - axis
    return turns


def four_point_by_hand(zs, gamma, clip=False):
    """One run of four-point averaging, written out: return its turns."""
    points = [(gamma, 0.0), (-gamma, 0.0), (0.0, gamma), (0.0, -gamma)]
    phase, v = 0, [0.0] * 4
    turns = []
    for z in zs:
        if z is None or math.isnan(z):
            turns.append((0.0, 0.0))
            continue
        v[phase] = z
        mean_turn = [0.0, 0.0]
        if phase == 3:
            v3 = sum(v) / 4.0
            for axis, (plus, minus) in enumerate(((v[0], v[1]), (v[2], v[3]))):
                total = plus + minus + v3
                p = gamma * (plus - minus) / total if total != 0.0 else 0.0
                if clip:
                    p = max(-gamma, min(gamma, p)) if total > 0.0 else 0.0
                mean_turn[axis] = p
        nxt = (phase + 1) % 4
        turns.append((mean_turn[0] + points[nxt][0] - points[phase][0],
                      mean_turn[1] + points[nxt][1] - points[phase][1]))
        phase = nxt
    return turns


def samples(rng, steps, runs):
    """Random positive samples with about one in six missing (NaN)."""
    z = rng.uniform(0.1, 3.0, (steps, runs))
    z[rng.random((steps, runs)) < 1.0 / 6.0] = np.nan
    return z


def test_hill_climbing_turns_one_axis_at_a_time_and_reverses_it_on_a_drop():
    hc = TwoAxisHillClimbing(gamma=2.0)
    assert hc.step(0.00, 1.0).tolist() == [[2.0, 0.0]]      # azimuth first, +gamma
    assert hc.step(0.05, 1.5).tolist() == [[0.0, 2.0]]      # rose: elevation, +gamma
    # dropped after elevation's turn: elevation reverses, azimuth keeps its direction
    assert hc.step(0.10, 1.2).tolist() == [[2.0, 0.0]]
    assert hc.step(0.15, 1.3).tolist() == [[0.0, -2.0]]
    assert hc.step(0.20, None).tolist() == [[0.0, 0.0]]     # missing: wait in place


@pytest.mark.parametrize('clip', [False, True])
def test_four_point_visits_the_cross_and_turns_by_eq26_per_axis(clip):
    fp = FourPointAveraging(gamma=2.0, clip=clip)
    assert fp.scan_offset.tolist() == [[2.0, 0.0]]
    assert fp.step(0.00, 3.0).tolist() == [[-4.0, 0.0]]     # +c -> -c
    assert fp.step(0.05, 1.0).tolist() == [[2.0, 2.0]]      # -c -> +e
    assert fp.step(0.10, 2.0).tolist() == [[0.0, -4.0]]     # +e -> -e
    # -e -> the new mean's +c: gamma_p = 2 (3 - 1) / (3 + 1 + 2) on c, 0 on e (V3 = 2)
    turn = fp.step(0.15, 2.0)[0]
    assert turn == pytest.approx([2.0 * 2.0 / 6.0 + 2.0, 2.0], abs=1e-15)
    assert fp.scan_offset.tolist() == [[2.0, 0.0]]


def test_the_vectorised_baselines_match_runs_stepped_by_hand():
    rng = np.random.default_rng(5)
    z = samples(rng, 60, 4)
    for aligner, by_hand in ((TwoAxisHillClimbing(1.5, runs=4),
                              lambda zs: hill_by_hand(zs, 1.5)),
                             (FourPointAveraging(1.5, runs=4),
                              lambda zs: four_point_by_hand(zs, 1.5)),
                             (FourPointAveraging(1.5, runs=4, clip=True),
                              lambda zs: four_point_by_hand(zs, 1.5, clip=True))):
        turns = np.array([aligner.step(0.05 * k, z[k]) for k in range(len(z))])
        for run in range(4):
            assert turns[:, run] == pytest.approx(np.array(by_hand(list(z[:, run]))),
                                                  abs=1e-12)


def test_four_point_clip_bounds_a_turn_the_printed_form_lets_blow_up():
    # noise can make V+ + V- + V3 nearly 0: (26) as printed then turns far; clip does not
    zs = [1.0, -0.9, 0.0, -0.05]
    wild = four_point_by_hand(zs, 2.0)[-1]
    assert abs(wild[0] - 2.0) > 10.0
    fp = FourPointAveraging(gamma=2.0, clip=True)
    turn = [fp.step(0.05 * k, z) for k, z in enumerate(zs)][-1][0]
    assert turn == pytest.approx([2.0 + 2.0, 2.0], abs=1e-12)     # gamma_p = +gamma (clipped)


@pytest.mark.parametrize('offset0', [5.0, 14.0])
def test_on_a_still_noiseless_source_each_baseline_converges(offset0):
    # beta 0, no random walk, no noise: hill climbing ends in a limit cycle of steps of
    # gamma = 2 deg per axis within 5 deg of the source; four-point settles within 1.5 deg.
    # Not at 0: the mount turns by joint angles at the receiver's elevation, so the cross's
    # azimuth legs (at e and at e +- gamma) do not close and the cross creeps in azimuth by
    # about 2 gamma (1/cos(e - gamma) - 1/cos e) per cycle, which (26) holds off at an
    # offset (0.5-0.6 deg at 20 deg elevation); the elevation error goes to 0 (< 0.5 deg)
    link = PanTiltLinkConfig(noise=0.0, beta=0.0, q_sys=(0.0, 0.0), steps=400,
                             offset0=offset0)
    for aligner, within in ((TwoAxisHillClimbing(runs=50), 5.0),
                            (FourPointAveraging(runs=50), 1.5)):
        traj = simulate_pan_tilt(aligner, link, np.random.default_rng(1))
        d = np.hypot(traj.error[..., 0], traj.error[..., 1])
        # the source starts offset0 off the boresight (hill climbing has no scan offset)
        if isinstance(aligner, TwoAxisHillClimbing):
            assert traj.theta[0] == pytest.approx(np.full(50, offset0), rel=1e-9)
        else:
            assert np.max(np.abs(traj.error[-100:, :, 1])) < 0.5
        assert np.max(d[-100:]) < within, type(aligner).__name__


@pytest.mark.parametrize('bad', [0.0, -1.0, float('nan'), float('inf')])
def test_a_bad_step_is_refused(bad):
    for cls in (TwoAxisHillClimbing, FourPointAveraging):
        with pytest.raises(AlignmentError, match='gamma must be positive'):
            cls(bad)
