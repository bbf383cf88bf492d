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

"""
Where a pan-tilt receiver points, on the sphere and in the small-angle tangent plane.

A two-joint mount turns by azimuth a (pan, about the vertical) and elevation e (tilt);
its boresight is the unit vector b(a, e) = [cos e cos a, cos e sin a, sin e].  The LED is
seen along s(a_s, e_s).  The simulation measures the exact off-axis angle
theta = atan2(|b x s|, b . s) on the sphere; the filter and the controllers work in the
tangent plane at the source, with the pointing error

    d = [d_c, d_e] = [wrap(a - a_s) cos e_s, e - e_s]          (degrees)

(cross-elevation and elevation), where theta ~ |d| to second order in the angles.  A
turn of the boresight by [du_c, du_e] in that plane is the joint turn
[du_c / cos e, du_e]: a pan axis near the zenith needs large turns for small
cross-elevation steps (the keyhole), so the elevations are kept within +-MAX_ELEVATION.
"""

import math
from typing import Union

import numpy as np

from tskf_ros.led.intensity_model import AlignmentError, FloatArray, wrap_degrees

Angles = Union[float, FloatArray]

MAX_ELEVATION = 80.0            # degrees: the keyhole limit of the tilt joint


def boresight(azimuth: Angles, elevation: Angles) -> FloatArray:
    """Return the unit vectors b(a, e), shape (..., 3), for angles in degrees."""
    a = np.radians(np.asarray(azimuth, dtype=float))
    e = np.radians(np.asarray(elevation, dtype=float))
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)


def off_axis_angle(azimuth: Angles, elevation: Angles, source_azimuth: Angles,
                   source_elevation: Angles) -> FloatArray:
    """Return the exact angle (degrees) between the boresight and the source direction."""
    b = boresight(azimuth, elevation)
    s = boresight(source_azimuth, source_elevation)
    # atan2(|b x s|, b . s): accurate at small and at large angles, unlike arccos(b . s)
    cross = np.linalg.norm(np.cross(b, s), axis=-1)
    return np.degrees(np.arctan2(cross, np.sum(b * s, axis=-1)))


def tangent_error(azimuth: Angles, elevation: Angles, source_azimuth: Angles,
                  source_elevation: Angles) -> FloatArray:
    """Return d = [wrap(a - a_s) cos e_s, e - e_s] (degrees), shape (..., 2)."""
    a = np.asarray(azimuth, dtype=float)
    e = np.asarray(elevation, dtype=float)
    a_s = np.asarray(source_azimuth, dtype=float)
    e_s = np.asarray(source_elevation, dtype=float)
    cross = wrap_degrees(a - a_s) * np.cos(np.radians(e_s))
    return np.stack(np.broadcast_arrays(cross, e - e_s), axis=-1)


def joint_turn(turn: FloatArray, elevation: Angles) -> FloatArray:
    """Return the joint turns [da, de] (degrees) for tangent-plane turns [du_c, du_e]."""
    turn = np.asarray(turn, dtype=float)
    cos_e = np.cos(np.radians(np.asarray(elevation, dtype=float)))
    return np.stack(np.broadcast_arrays(turn[..., 0] / cos_e, turn[..., 1]), axis=-1)


def conical_scan(radius: float, points: int) -> FloatArray:
    """
    Return the scan offsets r [cos phi_j, sin phi_j], phi_j = 2 pi j / points, shape (points, 2).

    The receiver visits them cyclically around its mean pointing (a conical scan, as in
    conical-scan radar and free-space optical trackers); the phase of each sample is known
    because the controller commands it.
    """
    if not (math.isfinite(radius) and radius > 0.0):
        raise AlignmentError(f'the scan radius must be positive, got {radius}')
    if points < 3:
        raise AlignmentError(f'a conical scan needs at least 3 points per turn, got {points}')
    phase = 2.0 * np.pi * np.arange(points) / points
    return radius * np.stack([np.cos(phase), np.sin(phase)], axis=-1)


def uniform_in_cone(half_angle: float, runs: int, rng: 'np.random.Generator') -> FloatArray:
    """
    Return offsets d (runs, 2), degrees, whose directions are uniform in solid angle in a cone.

    The solid angle within theta of an axis is 2 pi (1 - cos theta), so cos theta is
    uniform on [cos half_angle, 1]; the direction around the axis is uniform.  |d| is the
    exact angle theta (the offsets are meant for `displaced`).
    """
    cos_max = math.cos(math.radians(half_angle))
    theta = np.degrees(np.arccos(1.0 - rng.random(runs) * (1.0 - cos_max)))
    phase = rng.uniform(0.0, 2.0 * np.pi, runs)
    return theta[:, None] * np.stack([np.cos(phase), np.sin(phase)], axis=-1)


def displaced(azimuth: Angles, elevation: Angles, offset: FloatArray) -> FloatArray:
    """
    Return the joints [a, e] (..., 2) of the direction at the exact angle |d| from b(a, e).

    The great circle from b(a, e) toward the tangent direction d = [d_c, d_e] (the
    exponential map of the sphere): p = cos|d| b + sin|d| (d_c t_c + d_e t_e) / |d| with
    t_c = [-sin a, cos a, 0] and t_e = [-sin e cos a, -sin e sin a, cos e];
    off_axis_angle(b, p) = |d| exactly (|d| < 180).
    """
    a = np.radians(np.asarray(azimuth, dtype=float))
    e = np.radians(np.asarray(elevation, dtype=float))
    d = np.asarray(offset, dtype=float)
    r = np.radians(np.hypot(d[..., 0], d[..., 1]))
    safe = np.where(r > 0.0, r, 1.0)
    u_c, u_e = np.radians(d[..., 0]) / safe, np.radians(d[..., 1]) / safe
    b = boresight(np.degrees(a), np.degrees(e))
    t_c = np.stack([-np.sin(a), np.cos(a), np.zeros_like(a)], axis=-1)
    t_e = np.stack([-np.sin(e) * np.cos(a), -np.sin(e) * np.sin(a), np.cos(e)], axis=-1)
    p = (np.cos(r)[..., None] * b
         + np.sin(r)[..., None] * (u_c[..., None] * t_c + u_e[..., None] * t_e))
    az = np.degrees(np.arctan2(p[..., 1], p[..., 0]))
    el = np.degrees(np.arcsin(np.clip(p[..., 2], -1.0, 1.0)))
    return np.stack([az, el], axis=-1)


def log_offset(azimuth: Angles, elevation: Angles, to_azimuth: Angles,
               to_elevation: Angles) -> FloatArray:
    """
    Return d (..., 2) with displaced(a, e, d) = (to_a, to_e): the inverse of `displaced`.

    |d| is the exact angle between the two directions and its direction the great
    circle's at b(a, e) in the [t_c, t_e] frame (the logarithm map of the sphere).
    """
    a = np.radians(np.asarray(azimuth, dtype=float))
    e = np.radians(np.asarray(elevation, dtype=float))
    p = boresight(to_azimuth, to_elevation)
    t_c = np.stack([-np.sin(a), np.cos(a), np.zeros_like(a)], axis=-1)
    t_e = np.stack([-np.sin(e) * np.cos(a), -np.sin(e) * np.sin(a), np.cos(e)], axis=-1)
    u = np.stack([np.sum(p * t_c, axis=-1), np.sum(p * t_e, axis=-1)], axis=-1)
    norm = np.hypot(u[..., 0], u[..., 1])
    theta = off_axis_angle(azimuth, elevation, to_azimuth, to_elevation)
    return np.where(norm[..., None] > 0.0, u / np.maximum(norm, 1e-300)[..., None], 0.0) \
        * theta[..., None]


def turn_between(joints: FloatArray, target: FloatArray) -> FloatArray:
    """
    Return the tangent-plane turn (..., 2) that `joint_turn` at joints' tilt makes target.

    [wrap(a' - a) cos e, e' - e]: the inverse of joint_turn, so a mount at `joints` that
    executes it reaches `target` exactly.
    """
    joints = np.asarray(joints, dtype=float)
    target = np.asarray(target, dtype=float)
    cos_e = np.cos(np.radians(joints[..., 1]))
    return np.stack([wrap_degrees(target[..., 0] - joints[..., 0]) * cos_e,
                     target[..., 1] - joints[..., 1]], axis=-1)


def closed_scan_turn(turn: FloatArray, s_now: FloatArray, s_next: FloatArray,
                     tilt: Angles) -> FloatArray:
    """
    Return the tangent-plane turn (..., 2) that moves the mean pointing by `turn` exactly.

    The boresight at tilt is the mean pointing m plus the scan offset s_now, in joints
    m + joint_turn(s_now, tilt) (as the simulation reads the mean pointing); the mean moves
    by `turn` at its own tilt, m' = m + joint_turn(turn, m_e), and the receiver goes to
    m' + joint_turn(s_next, m'_e + s_next_e).  Sent as `turn_between` the two, the scan's
    circle closes in joints.  The plain turn + s_next - s_now, executed at the boresight's
    tilt, does not: over a circle of radius r at elevation e the mean pointing creeps in
    cross-elevation by about pi r^2 tan e (radians; 0.32 deg per turn at r = 4 deg and
    e = 20 deg, 1.05 deg at 50 deg).
    """
    tilt = np.asarray(tilt, dtype=float)
    joints = np.stack([np.zeros_like(tilt), tilt], axis=-1)
    mean = joints - joint_turn(s_now, tilt)
    moved = mean + joint_turn(turn, mean[..., 1])
    after = moved + joint_turn(s_next, moved[..., 1] + np.asarray(s_next)[..., 1])
    return turn_between(joints, after)
