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

"""The two-axis supervisor: cold start in a cone, tracking, a held loss, by name."""

import numpy as np
import pytest
from sample_filter import SampleFilter

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.supervisor import LOST, TRACKING
from tskf_ros.led.two_axis.aligners import make_two_axis_aligner, METHODS
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig, ConicalScanEKF
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt, tracking_fraction
from tskf_ros.led.two_axis.pan_tilt_supervisor import PanTiltSupervisor
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig
from tskf_ros.led.two_axis.pointing_geometry import joint_turn, log_offset


def _acquired_within(theta, seconds, dt=0.05, window=20):
    """Per run: 20 samples in a row within 15 deg, starting at or before `seconds`."""
    ok = theta <= 15.0
    win = np.lib.stride_tricks.sliding_window_view(ok, window, axis=0).all(-1)
    first = np.where(win.any(0), win.argmax(0), 10**9) * dt
    return first <= seconds


def test_cold_start_in_a_30_degree_cone_at_1_volt():
    """
    Uniform in a 30 deg cone, 1 V: acquired within 10 s in >= 95 % of 300 runs.

    Over 1000 runs (alignment_mc --axes 2 --cold-start 30, seeds 0-6): 99.4 to 99.7 %; the
    goal is 99 %.
    """
    aligner = make_two_axis_aligner('conical_ekf_pat', runs=300, noise=1.0, start='acquiring')
    traj = simulate_pan_tilt(aligner, PanTiltLinkConfig(noise=1.0, cone=30.0), 4)
    assert np.mean(_acquired_within(traj.theta, 10.0)) >= 0.95


def test_tracks_at_1_volt_with_the_supervisor():
    """At beta 1.2 deg/s per axis, 1 V, 300 runs: >= 99 % of samples within 15 deg."""
    aligner = make_two_axis_aligner('conical_ekf_pat', runs=300, noise=1.0)
    traj = simulate_pan_tilt(aligner, PanTiltLinkConfig(noise=1.0), 5)
    assert np.mean(tracking_fraction(traj)) >= 0.99


# the filter told the 0.5 V of the links below (with the default 0.2 V, a run now and then
# loses its lock before the light is blocked, and the tests are about the block)
TOLD_05 = ConicalEKFConfig(noise=0.5)


def test_a_block_of_the_light_is_held_and_tracking_resumes():
    """2 s with no light: the loss is declared, held (the EKF steers), then tracking again."""
    aligner = make_two_axis_aligner('conical_ekf_pat', runs=50, noise=0.5)
    link = PanTiltLinkConfig(noise=0.5, steps=300, blocked=(5.0, 7.0))
    traj = simulate_pan_tilt(aligner, link, 6)
    assert np.mean(aligner.losses >= 1) >= 0.9
    assert np.mean(aligner.state == TRACKING) >= 0.9
    assert np.mean(traj.theta[-1] <= 15.0) >= 0.9
    assert np.all(aligner.handovers == 0) or np.mean(aligner.handovers == 0) >= 0.8


def test_a_dark_read_as_missing_samples_is_not_taken_for_the_light_back():
    """
    Light blocked 2 to 12 s, the dark's negative readings missing (the node's default).

    About half the dark samples arrive, all of them low; a window with fewer low samples
    than `corroborate` is not steady unless at least half of it arrived, so no run goes
    back to tracking in the dark (before the rule, 30 of these 200 did, 45 times); 8 s
    after the light is back (the hold ran out, a search found it) 195 of 200 track.
    """
    sup = make_two_axis_aligner('conical_ekf_pat', runs=200, noise=0.2)
    back_in_the_dark = np.zeros(200, dtype=bool)

    def watch(stamp):
        if 2.5 < stamp < 12.0:
            back_in_the_dark[:] |= sup.changed & (sup.state == TRACKING)

    negative_is_missing = SampleFilter(sup, lambda stamp, z: np.where(z < 0.0, np.nan, z),
                                       watch)
    link = PanTiltLinkConfig(noise=0.2, steps=400, blocked=(2.0, 12.0))
    traj = simulate_pan_tilt(negative_is_missing, link, 3)
    assert np.mean(traj.z[100:200] < 0.0) > 0.4               # the dark: about half missing
    assert np.all(sup.losses >= 1) and not np.any(back_in_the_dark)
    assert np.mean(sup.state == TRACKING) >= 0.95


def test_a_loss_held_longer_than_hold_samples_becomes_a_search():
    """Light blocked for 10 s: after hold_samples the runs search (lost, not steering)."""
    sup = PanTiltSupervisor(ConicalScanEKF(TOLD_05, runs=20),
                            PanTiltSupervisorConfig(start='tracking', hold_samples=40,
                                                    fade_peak=0.0, hold_dark=False))
    link = PanTiltLinkConfig(noise=0.5, steps=200, blocked=(2.0, 12.0))
    simulate_pan_tilt(sup, link, 7)
    assert np.all(sup.state == LOST) and not np.any(sup.steering)


def _hold_in_the_dark(hold_dark: bool, noise: float = 1.0) -> PanTiltSupervisor:
    """Return the supervisor after a loss held 40 samples with no light from 2 s (6 s run)."""
    config = PanTiltSupervisorConfig(start='tracking', hold_samples=40, fade_peak=0.0,
                                     fade_hold=300, hold_after=0, hold_dark=hold_dark,
                                     noise=noise)
    sup = PanTiltSupervisor(ConicalScanEKF(TOLD_05, runs=20), config)
    simulate_pan_tilt(sup, PanTiltLinkConfig(noise=0.5, steps=120, blocked=(2.0, 12.0)), 7)
    return sup


def test_a_hold_that_runs_out_in_the_dark_is_held_on_as_a_fade():
    """
    hold_dark: a hold that runs out with x1hat g_r(0) under the detector's reference.

    The light blocked: the EKF's x1hat g_r(0) falls under k_ref (0.8 V) within the 40
    samples of the hold, which is then held on as a fade (fade_hold samples, steering)
    instead of a search.  With hold_dark False, or a noise of at least 2 k_ref (the light
    the CUSUM is set for), the runs search.
    """
    sup = _hold_in_the_dark(True)
    assert sup.config.holds_dark
    assert np.all(sup.x[:, 0] * sup.response.peak < sup.config.detector.reference)
    assert np.all(sup.state == LOST) and np.all(sup.steering)
    assert np.all(sup.fading) and np.all(sup.hold_limit == 300)
    for searching in (_hold_in_the_dark(False), _hold_in_the_dark(True, noise=1.6)):
        assert not searching.config.holds_dark
        assert np.all(searching.state == LOST) and not np.any(searching.steering)


def test_a_loss_of_a_dim_light_is_held_for_fade_hold():
    """A light dimmer in lock than fade_peak: its loss is held fade_hold samples, steering."""
    sup = PanTiltSupervisor(ConicalScanEKF(TOLD_05, runs=20),
                            PanTiltSupervisorConfig(start='tracking', hold_samples=40,
                                                    fade_peak=10.0, fade_hold=300,
                                                    fade_seen=False, hold_after=0))
    link = PanTiltLinkConfig(noise=0.5, steps=200, blocked=(2.0, 12.0))
    simulate_pan_tilt(sup, link, 7)
    assert np.all(sup.state == LOST) and np.all(sup.steering)
    assert np.all(sup.hold_limit == 300)


def _through_the_dark(drift_walk: float) -> tuple[float, float]:
    """
    Run 10 s of lock at 0.5 V, then 10 s with no light held as a fade (200 runs, seed 7).

    Return the fraction of runs with the boresight in the 15 deg cone at the end and the
    median error |bhat - b| of the drift estimate there (deg per step).
    """
    ekf = ConicalEKFConfig(noise=0.5, Q=(0.0025, 0.02, 0.02, drift_walk, drift_walk))
    sup = PanTiltSupervisor(ConicalScanEKF(ekf, runs=200),
                            PanTiltSupervisorConfig(start='tracking', noise=np.hypot(0.5, 0.2),
                                                    fade_peak=10.0, fade_hold=400,
                                                    fade_seen=False, hold_after=0))
    traj = simulate_pan_tilt(sup, PanTiltLinkConfig(noise=0.5, blocked=(10.0, 20.0)), 7)
    assert np.all(sup.steering)
    # the EKF's b is the drift of d, the source's drift with its sign turned
    error = np.linalg.norm(sup.x[:, 3:5] + traj.drift[-1], axis=1)
    return float(np.mean(traj.theta[-1] <= 15.0)), float(np.median(error))


def test_a_fade_hold_steers_through_the_dark_on_the_drift_of_the_lock():
    """
    The drift's walk at the link's size (the default Q): 10 s without light stay in the cone.

    With the default 1e-8 per step, bhat is the drift of the whole lock and stays it while
    the samples are noise alone: 96 % of the runs in the cone after 10 s in the dark,
    median |bhat - b| 0.020 deg per step; with a walk of 1e-5 per step the noise carries
    bhat off (0.062) and 34 % are in the cone.
    """
    assert ConicalEKFConfig().Q[3:] == (1e-8, 1e-8)
    kept, drift_error = _through_the_dark(1e-8)
    assert kept >= 0.9 and drift_error < 0.03
    kept_fast, drift_error_fast = _through_the_dark(1e-5)
    assert kept_fast < kept - 0.3 and drift_error_fast > 2.0 * drift_error


def test_a_light_never_seen_at_fade_peak_in_lock_has_not_faded():
    """fade_seen: x1_lock never reached fade_peak since the start, so hold_samples only."""
    sup = PanTiltSupervisor(ConicalScanEKF(TOLD_05, runs=20),
                            PanTiltSupervisorConfig(start='tracking', hold_samples=40,
                                                    fade_peak=10.0, fade_hold=300,
                                                    hold_after=0, hold_dark=False))
    link = PanTiltLinkConfig(noise=0.5, steps=200, blocked=(2.0, 12.0))
    simulate_pan_tilt(sup, link, 7)
    assert np.all(sup.x1_best * sup.response.peak < 10.0)
    assert np.all(sup.hold_limit == 40) and not np.any(sup.steering)


@pytest.mark.parametrize('hold_after, held', [(0, True), (40, False)])
def test_a_lock_younger_than_hold_after_is_not_held(hold_after, held):
    """Blocked at 2 s, about 20 samples after good lock: held only with hold_after 0."""
    sup = PanTiltSupervisor(ConicalScanEKF(TOLD_05, runs=20),
                            PanTiltSupervisorConfig(start='tracking', hold_samples=300,
                                                    hold_after=hold_after))
    simulate_pan_tilt(sup, PanTiltLinkConfig(noise=0.5, steps=120, blocked=(2.0, 12.0)), 7)
    assert np.all(sup.state == LOST) and np.all(sup.losses == 1)
    assert np.all(sup.lock_age < 40)
    assert np.all(sup.steering == held)


class _Watch:
    """The supervisor, with what each step left: looking, steering, the mean pointing."""

    def __init__(self, sup):
        self.sup, self.runs = sup, sup.runs
        self.looking, self.steering, self.mean, self.center = [], [], [], []
        self.drift = []

    @property
    def scan_offset(self):
        return self.sup.scan_offset

    def step(self, stamp, z):
        turn = self.sup.step(stamp, z)
        s = self.sup
        self.looking.append(s.looking.copy())
        self.steering.append(s.steering.copy())
        # the mean pointing of the next sample: the joints less the next scan offset
        self.mean.append(s.joints - joint_turn(s.scan_offset, s.joints[:, 1]))
        self.center.append(s.spiral.center.copy())
        self.drift.append(s.tracker.x[:, 3:5].copy())
        return turn


def test_a_fade_hold_looks_around_and_comes_back_to_the_held_pointing():
    """fade_look: one spiral pass (no light: blocked), then the hold at its moving centre."""
    config = PanTiltSupervisorConfig(start='tracking', hold_samples=20, fade_peak=10.0,
                                     fade_hold=40, fade_seen=False, fade_look=20.0,
                                     hold_after=0)
    # the reach is read on the mean pointing, the spiral's boresight less the scan offset:
    # 20 deg less r = 4 (the dim scan's 6.5 deg off, so that r is fixed)
    ekf = ConicalScanEKF(ConicalEKFConfig(dim_radius=0.0), runs=10)
    watch = _Watch(PanTiltSupervisor(ekf, config))
    simulate_pan_tilt(watch, PanTiltLinkConfig(noise=0.5, steps=300, blocked=(2.0, 15.0)), 7)
    looking, steering = np.array(watch.looking), np.array(watch.steering)
    mean, center = np.array(watch.mean), np.array(watch.center)
    drift = np.array(watch.drift)
    for r in range(10):
        k0 = int(np.argmax(looking[:, r]))          # the look's first sample
        assert looking[k0, r] and not steering[k0, r]
        k1 = k0 + int(np.argmax(~looking[k0:, r]))  # back to the hold
        assert steering[k1, r] and 10 < k1 - k0 < 60
        # the look went round its spiral, out to about fade_look from its centre
        away = log_offset(center[k0:k1, r, 0], center[k0:k1, r, 1], mean[k0:k1, r, 0],
                          mean[k0:k1, r, 1])
        assert np.max(np.hypot(*away.T)) > 15.0
        # and came back to the centre, which moved as the hold would have steered it
        np.testing.assert_allclose(mean[k1, r], center[k1, r], atol=1e-9)
        expected = mean[k0 - 1, r][None, :]         # where the look began, each sample
        for _ in range(k0, k1 + 1):                 # moved by -bhat of that sample
            expected = expected + joint_turn(-drift[k0, r][None, :], expected[:, 1])
        np.testing.assert_allclose(center[k1, r], expected[0], rtol=0, atol=1e-9)


def test_builds_every_method_by_name():
    """Every name of METHODS builds an aligner that steps; a cold start needs the supervisor."""
    for method in METHODS:
        aligner = make_two_axis_aligner(method, runs=2)
        assert aligner.step(0.0, [1.0, 2.0]).shape == (2, 2)
    with pytest.raises(AlignmentError, match='acquiring'):
        make_two_axis_aligner('conical_lqg', start='acquiring')
    with pytest.raises(AlignmentError, match='unknown'):
        make_two_axis_aligner('three_point')


def test_a_noiseless_cold_start_is_acquired_within_10_s():
    """
    0 V, 100 runs uniform in a 30 deg cone (seed 3): all acquired within 10 s.

    With the CUSUM's threshold fixed at 3 V and light seen only from the 10th sample on
    (threshold_sigmas 100, early_light False), 91 of these 100 were: a noiseless crossing
    of an arm keeps the CUSUM under 3 V (test_spot_detector).
    """
    aligner = make_two_axis_aligner('conical_ekf_pat', runs=100, noise=0.0, start='acquiring')
    traj = simulate_pan_tilt(aligner, PanTiltLinkConfig(noise=0.0, cone=30.0, steps=220), 3)
    assert np.all(_acquired_within(traj.theta, 10.0))


@pytest.mark.parametrize('early', [True, False])
def test_light_seen_in_the_first_samples_is_handed_over_at_min_samples(early):
    """
    3 V at the first three samples of a search, then 0 V.

    The CUSUM (h 3 V) sees light at the second sample and is under h again by the 6th.
    With early_light: the hand-over comes settle + refine samples after the search's
    min_samples-th sample; without it none comes.
    """
    config = PanTiltSupervisorConfig(early_light=early)
    aligner = make_two_axis_aligner('conical_ekf_pat', runs=1, noise=1.0, start='acquiring',
                                    supervisor=config)
    first = None
    for k in range(100):
        aligner.step(0.05 * k, np.array([3.0 if k < 3 else 0.0]))
        if first is None and aligner.handovers[0] > 0:
            first = k
    # sample k is the search's (k + 1)-th: the min_samples-th is k = min_samples - 1
    expected = config.min_samples - 1 + config.settle + aligner.refine_samples
    assert first == (expected if early else None)


@pytest.mark.parametrize('resume', [True, False])
def test_a_hand_over_that_never_locks_resumes_the_search_where_it_stopped(resume):
    """
    Dark for 40 samples, 3 V for 5, then dark: a hand-over, no good lock, a loss.

    With resume the spiral goes on from where the CUSUM stopped it (its phi no smaller);
    without it the spiral starts again at its centre.
    """
    config = PanTiltSupervisorConfig(resume=resume)
    sup = make_two_axis_aligner('conical_ekf_pat', runs=1, noise=0.5, start='acquiring',
                                supervisor=config)
    phi_at_handover = None
    for k in range(200):
        sup.step(0.05 * k, np.array([3.0 if 40 <= k < 45 else 0.0]))
        if phi_at_handover is None and sup.handovers[0] > 0:
            phi_at_handover = sup.spiral.phi[0]
        if sup.losses[0] > 0:
            break
    assert phi_at_handover is not None and phi_at_handover > 0.0
    assert sup.losses[0] == 1 and not sup.locked[0] and not sup.steering[0]
    if resume:
        assert sup.spiral.phi[0] >= phi_at_handover
    else:
        assert sup.spiral.phi[0] < phi_at_handover / 4
