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

"""Pan-tilt geometry: exact angles on the sphere, the tangent plane, joint turns."""

import math

import numpy as np
import pytest

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.two_axis.pointing_geometry import (boresight, closed_scan_turn,
                                                     conical_scan, displaced, joint_turn,
                                                     log_offset, off_axis_angle,
                                                     tangent_error, turn_between)


def test_off_axis_angle_is_the_angle_between_unit_vectors():
    """The angle is arccos(b . s) (degrees), away from 0 and 180 where arccos is accurate."""
    rng = np.random.default_rng(0)
    a, e, a2, e2 = rng.uniform(-180, 180, 200), rng.uniform(-80, 80, 200), \
        rng.uniform(-180, 180, 200), rng.uniform(-80, 80, 200)
    expected = np.degrees(np.arccos(np.sum(boresight(a, e) * boresight(a2, e2), axis=-1)))
    np.testing.assert_allclose(off_axis_angle(a, e, a2, e2), expected, atol=1e-6)


def test_small_angle_error_matches_the_exact_angle():
    """|d| = theta to 0.5 % at 1 deg, 5 % at 10 deg (first order in theta tan e_s, |e_s| <= 50)."""
    rng = np.random.default_rng(1)
    e_s = rng.uniform(-50, 50, 2000)
    for size, rel in ((1.0, 0.005), (10.0, 0.05)):
        phase = rng.uniform(0, 2 * np.pi, 2000)
        d = size * np.stack([np.cos(phase), np.sin(phase)], -1)
        p = displaced(np.zeros(2000), e_s, d)          # exact: theta = size
        approx = np.hypot(*tangent_error(p[:, 0], p[:, 1], 0.0, e_s).T)
        np.testing.assert_allclose(approx, size, rtol=rel)


def test_displaced_and_log_offset_are_inverse_and_exact():
    """displaced(b, d) is |d| from b; log_offset undoes it (to 1e-9 deg) up to 60 deg."""
    rng = np.random.default_rng(2)
    a, e = rng.uniform(-180, 180, 300), rng.uniform(-70, 70, 300)
    d = rng.uniform(-40, 40, (300, 2))
    p = displaced(a, e, d)
    np.testing.assert_allclose(off_axis_angle(a, e, p[:, 0], p[:, 1]), np.hypot(*d.T),
                               atol=1e-9)
    np.testing.assert_allclose(log_offset(a, e, p[:, 0], p[:, 1]), d, atol=1e-9)


def test_joint_turn_and_turn_between_are_inverse():
    """turn_between(j, j + joint_turn(u, e)) = u, with the pan wrapped."""
    rng = np.random.default_rng(3)
    joints = np.column_stack([rng.uniform(-180, 180, 100), rng.uniform(-70, 70, 100)])
    u = rng.uniform(-10, 10, (100, 2))
    np.testing.assert_allclose(turn_between(joints, joints + joint_turn(u, joints[:, 1])), u,
                               atol=1e-9)


def test_small_joint_turns_move_the_boresight_by_their_size():
    """A 0.1 deg tangent turn moves the boresight 0.1 deg (to 1e-4 deg) at any elevation."""
    e = np.linspace(-75, 75, 31)
    for u in ([0.1, 0.0], [0.0, 0.1], [0.06, -0.08]):
        j = joint_turn(np.tile(u, (31, 1)), e)
        np.testing.assert_allclose(off_axis_angle(0.0, e, j[:, 0], e + j[:, 1]),
                                   math.hypot(*u), atol=1e-4)


def test_conical_scan_is_a_circle_that_sums_to_zero():
    """The points are spaced on radius r; their sum is 0 (the scan's mean is the pointing)."""
    s = conical_scan(4.0, 20)
    np.testing.assert_allclose(np.hypot(*s.T), 4.0)
    np.testing.assert_allclose(s.sum(axis=0), 0.0, atol=1e-12)
    with pytest.raises(AlignmentError):
        conical_scan(0.0, 20)
    with pytest.raises(AlignmentError):
        conical_scan(4.0, 2)


def _scan_turns(elevation, closed, turns=1, u=(0.0, 0.0)):
    """
    Drive a mount round the scan; return its mean pointing at each step.

    The mount as the link's (joints += joint_turn(turn, tilt)), the mean pointing as the
    simulation reads it (the joints less joint_turn(s, tilt)).
    """
    scan = conical_scan(4.0, 20)
    joints = np.array([0.0, elevation]) + joint_turn(scan[0], elevation)
    means = [joints - joint_turn(scan[0], joints[1])]
    for k in range(20 * turns):
        s_now, s_next = scan[k % 20], scan[(k + 1) % 20]
        turn = (closed_scan_turn(np.array(u), s_now, s_next, joints[1]) if closed
                else np.array(u) + s_next - s_now)
        joints = joints + joint_turn(turn, joints[1])
        means.append(joints - joint_turn(s_next, joints[1]))
    return np.array(means)


@pytest.mark.parametrize('elevation', [0.0, 20.0, 50.0, -45.0])
def test_the_closed_scan_keeps_the_mean_pointing_still(elevation):
    """With closed_scan_turn and u = 0 the mean pointing stays where it was to 1e-9 deg."""
    means = _scan_turns(elevation, closed=True, turns=3)
    np.testing.assert_allclose(means - means[0], 0.0, rtol=0, atol=1e-9)


@pytest.mark.parametrize('elevation', [20.0, 50.0])
def test_the_plain_scan_creeps_by_pi_r_squared_tan_e_per_turn(elevation):
    """
    The turn u + s_{k+1} - s_k at the boresight's tilt: the mean creeps in cross-elevation.

    The azimuth legs of the circle are turned at tilts e + r sin phi, so a turn's joint
    azimuth is the integral of -r sin phi / cos(e + r sin phi) dphi, about
    -pi r^2 tan e / cos e (radians), pi r^2 tan e on the sky: a closed form to first order
    in r, so within 3 % at r = 4 deg (0.32 deg at 20 deg, 1.05 deg at 50 deg).
    """
    means = _scan_turns(elevation, closed=False)
    creep = abs(means[-1, 0] - means[0, 0]) * math.cos(math.radians(elevation))
    r = math.radians(4.0)
    expected = math.degrees(math.pi * r * r * math.tan(math.radians(elevation)))
    assert creep == pytest.approx(expected, rel=0.03)
    assert abs(means[-1, 1] - means[0, 1]) < 1e-9          # the tilt legs close


def test_the_closed_scan_turns_the_mean_pointing_by_u_at_its_own_tilt():
    """A turn u moves the mean pointing by joint_turn(u, its tilt), exactly."""
    u = np.array([0.7, -0.3])
    scan = conical_scan(4.0, 20)
    tilt = 50.0 + scan[3, 1]
    mean = np.array([0.0, tilt]) - joint_turn(scan[3], tilt)
    joints = np.array([0.0, tilt]) + joint_turn(closed_scan_turn(u, scan[3], scan[4], tilt),
                                                tilt)
    np.testing.assert_allclose(joints - joint_turn(scan[4], joints[1]),
                               mean + joint_turn(u, mean[1]), rtol=0, atol=1e-12)
