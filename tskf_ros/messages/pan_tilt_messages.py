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
Two-axis LED alignment messages: the pan-tilt command, its truth and its estimate.

As the one-axis messages (conversions.py): angles in messages are radians (REP 103), the
core's are degrees.  Types, all from common_interfaces:

- command: std_msgs/msg/Float64MultiArray with two entries, the absolute positions of the
  two joints in rad in the order of `pan_tilt.joints` ([pan, tilt] by default): what a
  ros2_control forward_command_controller with those two joints takes on
  <controller>/commands.  Its one layout dimension is labelled with the joint names,
  comma-separated (forward_command_controller reads only `data`).
- truth: sensor_msgs/msg/JointState: the two joints (scan included), the source's
  direction `source_azimuth`, `source_elevation`, and `off_axis`, the exact angle between
  the receiver's boresight and the source (rad).
- estimate: the estimate layout of conversions.py, the intensity in V and every angle of
  the state in rad (a drift per nominal step in rad per step), covariance to match.
"""

from typing import Sequence

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from tskf_ros.messages.conversions import (angle_to_msg, msg_to_angle, msg_to_state_estimate,
                                           state_estimate_to_msg, StateEstimate)
from tskf_ros.messages.parameter_schema import ParameterError

# the parameter naming the two joints (the alignment node checks it for one axis too)
JOINTS = 'pan_tilt.joints'

# the two-axis truth's entries after the two joints
SOURCE_JOINTS = ('source_azimuth', 'source_elevation')
OFF_AXIS = 'off_axis'
# the conical-scan EKF's states (core names) -> the estimate's state names (units)
STATE_LABELS = {
    'x1': 'x1_intensity_V',
    'd_c': 'd_cross_elevation_rad',
    'd_e': 'd_elevation_rad',
    'b_c': 'b_cross_elevation_rad_per_step',
    'b_e': 'b_elevation_rad_per_step',
}


def check_joints(values: dict) -> tuple[str, str]:
    """Return the two joint names; raise ParameterError (one line) if one is empty."""
    joints = tuple(values[JOINTS])
    if len(joints) != 2 or not all(isinstance(j, str) and j.strip() for j in joints):
        raise ParameterError(f'{JOINTS} must be two non-empty joint names, got {list(joints)}')
    return joints[0], joints[1]


def truth_joints(joints: Sequence[str]) -> tuple[str, ...]:
    """Return the truth JointState's names: the two joints, the source, off_axis."""
    return (*joints, *SOURCE_JOINTS, OFF_AXIS)


def pan_tilt_command_to_msg(angles_deg: Sequence[float],
                            joints: Sequence[str]) -> Float64MultiArray:
    """Convert absolute joint positions [pan, tilt] (deg) -> Float64MultiArray (rad)."""
    data = [float(a) for a in np.deg2rad(np.asarray(angles_deg, dtype=float))]
    layout = MultiArrayLayout(dim=[MultiArrayDimension(label=','.join(joints), size=len(data),
                                                       stride=len(data))])
    return Float64MultiArray(layout=layout, data=data)


def pan_tilt_truth_to_msg(stamp_ns: int, joints_deg: Sequence[float],
                          source_deg: Sequence[float], off_axis_deg: float,
                          joints: Sequence[str]) -> JointState:
    """Convert the two joints, the source direction and the off-axis angle (deg) -> JointState."""
    angles = np.deg2rad([*joints_deg, *source_deg, off_axis_deg])
    return angle_to_msg(stamp_ns, angles, truth_joints(joints))


def msg_to_pan_tilt_truth(msg: JointState) -> tuple[int, dict]:
    """Convert JointState -> (stamp ns, {name: angle deg})."""
    stamp, positions = msg_to_angle(msg)
    return stamp, dict(zip(msg.name, np.rad2deg(positions)))


def _scaling(states: Sequence[str]) -> np.ndarray:
    """Return diag(1, pi/180, ...): the intensity stays in V, every angle deg -> rad."""
    return np.diag([1.0 if s == 'x1' else np.pi / 180.0 for s in states])


def pan_tilt_state_to_msg(kind: str, stamp_ns: int, mu: float, x: np.ndarray, P: np.ndarray,
                          states: Sequence[str]) -> Float64MultiArray:
    """Convert a two-axis EKF state (V, deg) and covariance -> the estimate layout (V, rad)."""
    D = _scaling(states)
    n = len(states)
    return state_estimate_to_msg(kind, stamp_ns, mu,
                                 D @ np.asarray(x, dtype=float).reshape(n),
                                 D @ np.asarray(P, dtype=float).reshape(n, n) @ D,
                                 [STATE_LABELS[s] for s in states])


def msg_to_pan_tilt_state(msg: Float64MultiArray) -> StateEstimate:
    """Convert a two-axis estimate message -> StateEstimate in V and deg; ValueError if not one."""
    e = msg_to_state_estimate(msg)
    by_label = {label: state for state, label in STATE_LABELS.items()}
    if not e.names or any(name not in by_label for name in e.names):
        raise ValueError(f'not a two-axis alignment estimate: states {list(e.names)}')
    Dinv = np.linalg.inv(_scaling([by_label[name] for name in e.names]))
    return e._replace(x=Dinv @ e.x, P=Dinv @ e.P @ Dinv)
