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

"""The spiral search: exact on the sphere, its coverage and its length."""

import numpy as np
import pytest

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.two_axis.pointing_geometry import joint_turn, log_offset
from tskf_ros.led.two_axis.spiral_search import SpiralConfig, SpiralSearch


def _run(config, center, samples):
    search = SpiralSearch(config, 1)
    joints = np.array([center], dtype=float)
    search.start(np.ones(1, bool), joints)
    path = [joints[0].copy()]
    for _ in range(samples):
        joints = joints + joint_turn(search.turn(joints, np.ones(1, bool)), joints[:, 1])
        path.append(joints[0].copy())
    return search, np.array(path)


def test_the_path_covers_the_disc_within_half_a_pitch():
    """Every direction within 28 deg of the centre is within pitch/2 + speed of the path."""
    c = SpiralConfig()
    n = c.samples_to_cover(c.reach)
    _, path = _run(c, (10.0, 30.0), n)
    offsets = log_offset(10.0, 30.0, path[:, 0], path[:, 1])
    rng = np.random.default_rng(0)
    r = 28.0 * np.sqrt(rng.random(400))
    phase = rng.uniform(0, 2 * np.pi, 400)
    probe = r[:, None] * np.stack([np.cos(phase), np.sin(phase)], -1)
    gap = np.min(np.hypot(*(probe[:, None, :] - offsets[None]).transpose(2, 0, 1)), axis=1)
    assert gap.max() <= c.pitch / 2 + c.speed


def test_the_boresight_moves_speed_per_sample_and_reaches_the_reach():
    """Steps of about `speed` deg, 1.5 speed at most (the way back), out to `reach`."""
    c = SpiralConfig()
    n = c.samples_to_cover(c.reach)
    _, path = _run(c, (0.0, 20.0), n - 1)
    step = np.hypot(*np.diff(log_offset(0.0, 20.0, path[:, 0], path[:, 1]), axis=0).T)
    # the limit is on the tangent turn; on the sphere the step is up to 2 % longer
    assert np.all(step <= c.speed * 1.5 * 1.03)
    assert np.median(step) == pytest.approx(c.speed, rel=0.02)
    assert np.max(np.hypot(*log_offset(0.0, 20.0, path[:, 0], path[:, 1]).T)) == \
        pytest.approx(c.reach, abs=c.speed)


def test_samples_to_cover_is_the_spiral_length_over_speed():
    """The length is about pi R^2 / (pitch speed) for R >> pitch: within 5 % at R = 34."""
    c = SpiralConfig()
    assert c.samples_to_cover(34.0) == pytest.approx(np.pi * 34**2 / (c.pitch * c.speed),
                                                     rel=0.05)


def test_starts_again_beyond_the_reach():
    """After a whole spiral it starts another one around the same centre."""
    c = SpiralConfig()
    search, _ = _run(c, (0.0, 0.0), c.samples_to_cover(c.reach) + 20)
    assert search.spirals[0] == 1


def test_a_moving_centre_follows_its_rate_on_the_joints():
    """A rate [du_c, 0] per sample moves the centre du_c / cos e in pan per sample."""
    search = SpiralSearch(SpiralConfig(), 2)
    joints = np.array([[0.0, 30.0], [0.0, 30.0]])
    search.start(np.ones(2, bool), joints, rate=np.array([[0.1, 0.0], [0.0, 0.0]]))
    for _ in range(50):
        joints = joints + joint_turn(search.turn(joints, np.ones(2, bool)), joints[:, 1])
    np.testing.assert_allclose(search.center[0], [50 * 0.1 / np.cos(np.radians(30.0)), 30.0],
                               rtol=1e-12)
    np.testing.assert_array_equal(search.center[1], [0.0, 30.0])


def test_a_spiral_started_with_a_shorter_reach_starts_again_sooner():
    """A start with reach 20 starts again after samples_to_cover(20); 38 deg not yet."""
    c = SpiralConfig()
    search = SpiralSearch(c, 2)
    joints = np.zeros((2, 2))
    search.start(np.array([True, False]), joints, reach=20.0)
    search.start(np.array([False, True]), joints)
    for _ in range(c.samples_to_cover(20.0) + 1):
        joints = joints + joint_turn(search.turn(joints, np.ones(2, bool)), joints[:, 1])
    assert search.spirals.tolist() == [1, 0]


@pytest.mark.parametrize('bad', [{'speed': 0.0}, {'pitch': -1.0}, {'reach': 5.0}])
def test_bad_spirals_say_why(bad):
    """Each bad setting is one AlignmentError."""
    with pytest.raises(AlignmentError):
        SpiralConfig(**bad)


def test_a_spiral_left_and_resumed_goes_back_to_where_it_stopped():
    """Away 20 deg and back: it holds phi while it travels, then goes on from there."""
    c = SpiralConfig()
    search, _ = _run(c, (0.0, 20.0), 60)
    phi = search.phi[0]
    joints = np.array([[25.0, 20.0]])          # the mount elsewhere (a hand-over)
    for _ in range(20):
        turn = search.turn(joints, np.ones(1, bool))
        assert np.hypot(*turn[0]) <= c.speed * 1.5 + 1e-9
        joints = joints + joint_turn(turn, joints[:, 1])
        if search.phi[0] != phi:
            break
    # back on the path one step further along it than where it was left, not at the centre
    assert search.phi[0] > phi and search.spirals[0] == 0
    np.testing.assert_allclose(joints[0], search.point()[0], atol=1e-9)
    radius = np.hypot(*log_offset(0.0, 20.0, joints[0, 0], joints[0, 1]))
    assert radius >= c.pitch / (2 * np.pi) * phi


def _state(search):
    return [np.copy(getattr(search, name)) for name in
            ('center', 'rate', 'reach', 'phi', 'phase', 'spirals')]


def test_a_run_outside_the_mask_keeps_its_spiral_and_gets_no_turn():
    # two runs started, then each sample only run 0 searches: run 1's spiral stays where it
    # was, mid-travel or not, and its turn is zero; with no run in the mask (the tracking
    # node's case, which skips the work) nothing changes and every turn is zero
    search = SpiralSearch(SpiralConfig(), 2)
    joints = np.array([[0.0, 20.0], [40.0, -30.0]])
    search.start(np.ones(2, bool), joints)
    search.rate[:] = [[0.05, -0.02], [0.03, 0.01]]      # a centre that follows a drift
    for _ in range(5):
        joints = joints + joint_turn(search.turn(joints, np.ones(2, bool)), joints[:, 1])
    before = _state(search)
    only0 = np.array([True, False])
    for _ in range(300):        # past the reach: run 0 starts new spirals meanwhile
        turn = search.turn(joints, only0)
        assert np.all(turn[1] == 0.0)
        joints = joints + joint_turn(turn, joints[:, 1])
    after = _state(search)
    for old, new in zip(before, after):
        np.testing.assert_array_equal(old[1], new[1])
    assert search.spirals[0] > before[5][0]
    none = np.zeros(2, bool)
    before = _state(search)
    np.testing.assert_array_equal(search.turn(joints, none), np.zeros((2, 2)))
    for old, new in zip(before, _state(search)):
        np.testing.assert_array_equal(old, new)
