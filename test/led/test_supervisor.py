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

"""The acquiring / tracking / lost supervisor against scripted scenes (found, lost, re-found)."""

from dataclasses import dataclass
from typing import Optional

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.led.supervisor import (ACQUIRING, LOST, Supervisor, SupervisorConfig, TRACKING)

DT = led.PAPER_DT
RESPONSE = led.IncidenceResponse()
X1 = led.MAX_INTENSITY / RESPONSE.peak         # a 3 V peak


@dataclass
class Scene:
    """A scripted link: the light at `bearing` (deg), blocked in [start, stop) samples."""

    bearing: float
    blocked: tuple[tuple[int, int], ...] = ()
    noise: float = 0.0
    seed: int = 0
    fade: tuple[int, int, float] = (0, 0, 1.0)   # x1 falls linearly to this fraction

    def x1(self, k: int) -> float:
        """Return the light's intensity factor at sample k (V)."""
        start, stop, to = self.fade
        if k < start or stop <= start:
            return X1
        return X1 * (1.0 + (to - 1.0) * min(1.0, (k - start) / (stop - start)))


@dataclass
class Played:
    """What a scene did: per sample the state, declared losses and angle of incidence."""

    states: np.ndarray
    declared: np.ndarray
    phi: np.ndarray
    handovers: int = 0

    def transitions(self) -> list[tuple[int, int]]:
        """Return (sample, new state) at each change of state."""
        changes = np.nonzero(np.diff(self.states))[0] + 1
        return [(int(k), int(self.states[k])) for k in changes]


def play(scene: Scene, steps: int, tracker: str = 'ekf',
         config: Optional[SupervisorConfig] = None) -> Played:
    """Run one supervisor on the scene: z = x1 g(base + psi - bearing) + v, 0 when blocked."""
    sup = Supervisor(led.make_aligner(tracker, runs=1), config or SupervisorConfig(), RESPONSE)
    rng = np.random.default_rng(scene.seed)
    base = 0.0
    states, declared, phis = [], [], []
    for k in range(steps):
        phi = base - scene.bearing
        blocked = any(a <= k < b for a, b in scene.blocked)
        z = 0.0 if blocked else (scene.x1(k) * RESPONSE.g(phi)
                                 + scene.noise * rng.standard_normal())
        base += float(sup.step(k * DT, z)[0])
        states.append(int(sup.state[0]))
        declared.append(bool(sup.declared[0]))
        phis.append(phi)
    return Played(np.array(states), np.array(declared), np.array(phis), int(sup.handovers[0]))


@pytest.mark.parametrize('bearing, first_leg', [(-40.0, False), (35.0, True)])
def test_cold_start_finds_the_light_and_tracks(bearing, first_leg):
    played = play(Scene(bearing=bearing), 400)
    # one hand-over, no loss, in the tracking zone from then on
    (found, state), = played.transitions()
    assert state == TRACKING and not played.declared.any()
    # a cold search sweeps to +90 deg first, then to -90, at `speed` deg a sample: found
    # once the base is within the beam (|phi| < 10 deg), not later than the sweep's end
    sweep = led.supervisor.ScanConfig()
    travel = abs(bearing) - 10.0 if first_leg else 2 * sweep.half_width - bearing - 10.0
    assert travel / sweep.speed <= found <= sweep.worst_case_travel(cold=True) / sweep.speed
    if first_leg:
        assert found <= (abs(bearing) + 10.0) / sweep.speed
    assert np.all(np.abs(played.phi[found + 20:]) <= led.TRACKING_ANGLE)


@pytest.mark.parametrize('tracker', ['ekf', 'hill_climbing', 'three_point'])
def test_blocked_light_is_lost_and_found_again(tracker):
    config = SupervisorConfig(start='tracking')
    played = play(Scene(bearing=-5.0, blocked=((200, 260),)), 500, tracker, config)
    lost = [k for k, s in played.transitions() if s == LOST]
    found = [k for k, s in played.transitions() if s == TRACKING]
    assert len(lost) == 1 and len(found) == 1
    lock = config.lock
    if tracker == 'ekf':
        # the innovations confirm the loss once `corroborate` samples are low
        assert 200 + lock.corroborate - 1 <= lost[0] <= 200 + lock.low_count - 1
    else:
        # no innovations: the M-th low sample of the window declares it
        assert lost[0] == 200 + lock.low_count - 1
    # re-found once the light is back, and back in the tracking zone
    assert 260 < found[0] <= 260 + 40
    assert np.all(np.abs(played.phi[found[0] + 20:]) <= led.TRACKING_ANGLE)
    assert np.all(np.abs(played.phi[:200]) <= led.TRACKING_ANGLE)


@pytest.mark.parametrize('tracker', ['ekf', 'hill_climbing'])
def test_no_false_alarm_in_lock_with_noise_or_a_short_blockage(tracker):
    # 200 s at noise 1 V (the noise the thresholds are designed for) and a blockage
    # shorter than the evidence the tests need (with a margin for noisy low samples)
    config = SupervisorConfig(start='tracking')
    short = config.lock.corroborate - 2
    played = play(Scene(bearing=-5.0, noise=1.0, seed=0, blocked=((1000, 1000 + short),)),
                  4000, tracker, config)
    assert not played.declared.any()
    assert np.all(played.states == TRACKING)


def test_reset_mode_restarts_the_ekf_in_place():
    config = SupervisorConfig(start='tracking', reacquire=False)
    sup = Supervisor(led.make_aligner('ekf', runs=2), config, RESPONSE)
    for k in range(40):
        sup.step(k * DT, [2.5, 0.0])             # run 1 sees nothing: declared lost
    assert sup.losses[0] == 0 and sup.losses[1] >= 1
    assert np.all(sup.state == TRACKING)
    # the restarted run is back at Table I's x0 (the step's prediction adds its u = 0)
    # declared again within a window of dark samples, and restarted again
    for k in range(40, 40 + config.lock.window + 1):
        sup.step(k * DT, [2.5, 0.0])
        if sup.declared[1]:
            break
    assert sup.declared[1]
    np.testing.assert_allclose(sup.tracker.x[1], [led.PAPER_X0[0], 0.0], atol=1e-12)


def test_acquire_forces_a_search_around_the_current_angle():
    sup = Supervisor(led.make_aligner('hill_climbing', runs=1),
                     SupervisorConfig(start='tracking'), RESPONSE)
    sup.step(0.0, 2.0)
    sup.acquire()
    assert sup.state[0] == ACQUIRING and sup.changed[0]
    np.testing.assert_allclose(sup.sweep.center, sup.base)


def test_config_refuses_a_scan_faster_than_the_actuator():
    with pytest.raises(led.AlignmentError, match='exceeds max_step'):
        SupervisorConfig(max_step=2.0)
    with pytest.raises(led.AlignmentError, match='start must be one of'):
        SupervisorConfig(start='sleeping')


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('fade, lost', [(1.0, False), (0.0, True)])
def test_a_light_that_fades_under_the_noise_is_tracked_not_searched_for(fade, lost, seed):
    # x1 falls from 3 V to 0.3 V over 10 s at noise 0.5 V: the mean in lock follows it
    # under `fade` x noise (1 V), so a low intensity is not a pointing loss; without the rule the
    # M-of-N test declares one and the sweep, finding nothing, takes the receiver away
    config = SupervisorConfig(start='tracking', fade=fade)
    played = play(Scene(bearing=-5.0, fade=(100, 300, 0.1), noise=0.5, seed=seed), 500, 'ekf',
                  config)
    assert played.declared.any() == lost
    if not lost:
        assert np.all(played.states == TRACKING)
        assert np.all(np.abs(played.phi) <= led.TRACKING_ANGLE)


def test_a_block_after_a_partial_fade_is_still_a_loss():
    # dimmed to 70 % (its mean in lock still above the 1 V noise), then blocked: lost
    config = SupervisorConfig(start='tracking')
    played = play(Scene(bearing=-5.0, fade=(50, 150, 0.7), blocked=((300, 360),)), 400,
                  'ekf', config)
    assert [s for _, s in played.transitions()][:1] == [LOST]
    assert not played.declared[:300].any()


@pytest.mark.parametrize('clip, want', [(True, (4.0, 25.0)), (False, (100.0, 1000.0))])
def test_a_known_start_ekf_starts_from_the_clipped_prior(clip, want):
    config = SupervisorConfig(start='tracking', clip_prior=clip)
    sup = Supervisor(led.make_aligner('ekf', runs=3), config, RESPONSE)
    np.testing.assert_allclose(sup.tracker.P, np.tile(np.diag(want), (3, 1, 1)))
    np.testing.assert_allclose(sup.tracker.x, np.tile(led.PAPER_X0, (3, 1)))


@pytest.mark.parametrize('after', [14, 18, 22, 26])
def test_a_block_right_after_the_hand_over_is_a_loss(after):
    # the mean in lock holds a few samples then; the dark ones must not make it a faded
    # light (or a dim one whose low level is 0) before it counts
    found = play(Scene(bearing=-40.0), 200).transitions()[0][0]
    block = (found + after, found + after + 78)
    played = play(Scene(bearing=-40.0, blocked=(block,), noise=1.0, seed=1), block[1] + 60)
    assert played.declared[block[0]:block[1]].any()


@pytest.mark.parametrize('fade', [1.0, 0.7])
@pytest.mark.parametrize('tracker, handovers', [('ekf', 0), ('hill_climbing', 1)])
def test_a_loss_is_held_by_the_ekf_and_searched_for_by_a_baseline(tracker, handovers, fade):
    # blocked for 2.5 s, the light at full strength or dimmed to 70 %: the EKF holds (keeps
    # steering, no sweep) and is tracking again within a window of the light's return, with
    # no hand-over; hill-climbing searches and needs one
    config = SupervisorConfig(start='tracking')
    played = play(Scene(bearing=-5.0, fade=(50, 150, fade), blocked=((250, 300),)), 400,
                  tracker, config)
    (lost, s1), (found, s2) = played.transitions()[:2]
    assert (s1, s2) == (LOST, TRACKING)
    assert 250 + config.lock.corroborate - 1 <= lost <= 250 + config.lock.low_count - 1
    assert played.handovers == handovers
    if tracker == 'ekf':
        assert 300 < found <= 300 + config.lock.window
        assert played.declared.sum() == 1
    else:
        # the sweep's first leg reaches 15 deg past the last good angle
        assert np.max(np.abs(played.phi[lost:found])) > led.TRACKING_ANGLE + 10.0


@pytest.mark.parametrize('hold_samples', [0, 100])
def test_a_held_loss_turns_into_a_search_after_hold_samples(hold_samples):
    # blocked for 10 s: the hold ends after hold_samples and the sweep widens from there
    config = SupervisorConfig(start='tracking', hold_samples=hold_samples)
    played = play(Scene(bearing=-5.0, fade=(50, 150, 0.7), blocked=((250, 450),)), 450,
                  'ekf', config)
    lost = played.transitions()[0][0]
    assert played.states[lost] == LOST and np.all(played.states[lost:] == LOST)
    search = lost + hold_samples + 1
    # holding: the EKF's own scan keeps it near the light; searching: the legs widen
    assert np.max(np.abs(played.phi[lost:search])) < led.TRACKING_ANGLE + 5.0
    assert np.max(np.abs(played.phi[search:])) > 3 * led.TRACKING_ANGLE


def test_config_refuses_a_negative_hold():
    with pytest.raises(led.AlignmentError, match='hold_samples must be >= 0'):
        SupervisorConfig(hold_samples=-1)
