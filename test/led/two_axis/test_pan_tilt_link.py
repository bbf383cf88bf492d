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

"""The two-axis link: a seeded stream, and the closed loop that steps it."""

import math

import numpy as np
import pytest

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.two_axis.conical_ekf import ConicalScanEKF
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt
from tskf_ros.led.two_axis.pointing_geometry import joint_turn, off_axis_angle


def test_simulation_is_the_link_stepped_by_hand():
    """simulate_pan_tilt of one run equals a hand loop over PanTiltLink, same seed, exactly."""
    link = PanTiltLinkConfig(steps=120, noise=1.0, dropout=0.1, jitter=0.01)
    traj = simulate_pan_tilt(ConicalScanEKF(), link, 7)
    plant, ekf = PanTiltLink(link, seed=7), ConicalScanEKF()
    for k in range(link.steps):
        s = plant.sample()
        assert s.t == traj.t[k]
        np.testing.assert_array_equal(s.theta, traj.theta[k])
        np.testing.assert_array_equal(s.z, traj.z[k])
        turn = ekf.step(s.t, s.z)
        np.testing.assert_array_equal(turn, traj.turn[k])
        plant.command(plant.joints + joint_turn(turn, plant.joints[:, 1]))


def test_runs_of_one_seed_see_the_same_link_whatever_the_commands():
    """The noise stream does not depend on the commands: x1 and the source agree."""
    a, b = PanTiltLink(seed=3, runs=4), PanTiltLink(seed=3, runs=4)
    for _ in range(30):
        sa, sb = a.sample(), b.sample()
        np.testing.assert_array_equal(sa.x1, sb.x1)
        np.testing.assert_array_equal(sa.source, sb.source)
        np.testing.assert_allclose(sa.reading - sa.clean, sb.reading - sb.clean, atol=1e-12)
        b.command(b.joints + 1.0)


def test_first_sample_is_offset0_off_the_boresight():
    """Sample 0: the source exactly offset0 from the boresight, z = x1 g_r(theta) + v."""
    plant = PanTiltLink(PanTiltLinkConfig(offset0=5.0, noise=0.0), runs=50, seed=1)
    s = plant.sample()
    np.testing.assert_allclose(s.theta, 5.0, atol=1e-9)
    np.testing.assert_allclose(s.reading, s.x1 * plant.response.g(s.theta), rtol=1e-12)
    np.testing.assert_allclose(s.x1 * plant.response.peak, 3.0, rtol=1e-12)


def test_drift_moves_the_source_beta_per_second_per_axis():
    """No walk: after 1 s each joint of the source has moved beta = 1.2 deg."""
    c = PanTiltLinkConfig(q_sys=(0.0, 0.0), beta=1.2)
    plant = PanTiltLink(c, runs=20, seed=2)
    first = plant.sample().source
    for _ in range(20):
        last = plant.sample().source
    np.testing.assert_allclose(np.abs(last - first), 1.2, atol=1e-9)


def test_jittered_stamps_move_the_plant_by_the_elapsed_time():
    """With jitter the drift over a sample interval is beta times its length."""
    c = PanTiltLinkConfig(q_sys=(0.0, 0.0), jitter=0.02, beta=2.0)
    plant = PanTiltLink(c, runs=3, seed=4)
    prev = plant.sample()
    for _ in range(10):
        s = plant.sample()
        assert 0.01 < s.t - prev.t < 0.09
        np.testing.assert_allclose(np.abs(s.source[:, 1] - prev.source[:, 1]),
                                   2.0 * (s.t - prev.t), rtol=1e-9)
        prev = s


def test_cold_start_is_uniform_in_solid_angle():
    """theta_0 in a 30 deg cone: P(theta <= t) = (1 - cos t) / (1 - cos 30), 4000 runs."""
    s = PanTiltLink(PanTiltLinkConfig(cone=30.0), runs=4000, seed=5).sample()
    assert s.theta.max() <= 30.0 + 1e-9
    for t in (10.0, 20.0, 25.0):
        expected = (1 - math.cos(math.radians(t))) / (1 - math.cos(math.radians(30.0)))
        # binomial standard error at 4000 runs is at most 0.008: 4 of them
        assert abs(np.mean(s.theta <= t) - expected) < 0.032


def test_commands_move_the_mount_at_the_next_sample():
    """A [pan, tilt] command is where the boresight is at the next sample."""
    plant = PanTiltLink(seed=0)
    plant.sample()
    plant.command([3.0, 25.0])
    s = plant.sample()
    np.testing.assert_array_equal(s.joints, [[3.0, 25.0]])
    np.testing.assert_allclose(s.theta, off_axis_angle(3.0, 25.0, *s.source[0]), rtol=1e-12)


@pytest.mark.parametrize('bad', [{'dropout': 1.0}, {'jitter': 0.03}, {'cone': 95.0},
                                 {'elevation0': 60.0}, {'noise': math.nan},
                                 {'blocked': (3.0, 1.0)}])
def test_bad_link_configs_say_why(bad):
    """Each bad setting is one AlignmentError."""
    with pytest.raises(AlignmentError):
        PanTiltLinkConfig(**bad)


def test_non_finite_command_is_refused():
    """A NaN joint command raises, the mount stays."""
    plant = PanTiltLink(seed=0)
    with pytest.raises(AlignmentError, match='finite'):
        plant.command([math.nan, 0.0])
