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

"""Messages to and from the core: the only place where ROS messages meet numpy arrays."""

from typing import NamedTuple, Sequence, TYPE_CHECKING

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from sensor_msgs.msg import Illuminance, JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from tskf_ros.core.diagnostic_status import Status
from tskf_ros.core.units import NS

if TYPE_CHECKING:   # imported where it is built: geometry_msgs.msg loads its 35 types
    from geometry_msgs.msg import AccelStamped

SLOTS = 6
# the simulators' truth: joints (angles) by name
STATES_TYPE = 'sensor_msgs/msg/JointState'
# the estimates of both filter nodes: a stamped state vector with its covariance
STATE_ESTIMATE_TYPE = 'std_msgs/msg/Float64MultiArray'
LEVELS = {'OK': DiagnosticStatus.OK, 'WARN': DiagnosticStatus.WARN,
          'ERROR': DiagnosticStatus.ERROR, 'STALE': DiagnosticStatus.STALE}


def stamp_to_ns(stamp: Time) -> int:
    """Convert builtin_interfaces/Time -> integer nanoseconds."""
    return sec_nanosec_to_ns(stamp.sec, stamp.nanosec)


def sec_nanosec_to_ns(sec: int, nanosec: int) -> int:
    """Convert a stamp's sec and nanosec fields -> integer nanoseconds."""
    return int(sec) * NS + int(nanosec)


def ns_to_stamp(ns: int) -> Time:
    """Convert Integer nanoseconds (>= 0) -> builtin_interfaces/Time."""
    sec, nanosec = divmod(int(ns), NS)
    return Time(sec=sec, nanosec=nanosec)


def power_to_msg(stamp_ns: int, power: float, variance: float = 0.0, *,
                 frame_id: str = 'power_meter') -> Illuminance:
    """Convert (stamp, power mW, variance mW^2) -> Illuminance."""
    msg = Illuminance(illuminance=float(power), variance=float(variance))
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    return msg


def msg_to_power(msg: Illuminance) -> tuple[int, float, float]:
    """Convert Illuminance -> (stamp ns, power mW, variance mW^2)."""
    return stamp_to_ns(msg.header.stamp), float(msg.illuminance), float(msg.variance)


def angle_to_msg(stamp_ns: int, angles: Sequence[float], names: Sequence[str], *,
                 frame_id: str = '') -> JointState:
    """Convert True angle(s) (rad) -> JointState with the given joint names."""
    msg = JointState(name=list(names), position=[float(a) for a in angles])
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    return msg


def msg_to_angle(msg: JointState) -> tuple[int, np.ndarray]:
    """Convert JointState -> (stamp ns, positions)."""
    return stamp_to_ns(msg.header.stamp), np.array(msg.position, dtype=float)


# -- estimates of the filter nodes: std_msgs/msg/Float64MultiArray ----------------------
#
# common_interfaces has no stamped state vector with a covariance (doc/interfaces.md): the
# geometry types give their slots a meaning (an angle is no linear velocity), JointState
# has no covariance, and the stamped scalars hold one value.  An estimate is therefore a
# Float64MultiArray whose layout says what it holds:
#
#   data[0], data[1]   the stamp t_k: sec, nanosec (exact in a float64)
#   data[2]            mu (s): the graininess of the filter step the estimate comes from
#   layout.data_offset = 3: the three entries above are the array's leading padding
#   dim[0]: label = the kind ('predicted', 'corrected', 'smoothed'), size n + 1,
#           stride (n + 1) n: row 0 is the mean x, rows 1..n the covariance P
#   dim[1]: label = the state names, comma-separated, size n, stride n
#
# so that array(i, j) = data[3 + n i + j]: x_j = data[3 + j], P_ij = data[3 + n + n i + j].

ESTIMATE_OFFSET = 3


class StateEstimate(NamedTuple):
    """An estimate read from its message: kind, stamp (ns), mu (s), x, P, state names."""

    kind: str
    stamp_ns: int
    mu: float
    x: np.ndarray
    P: np.ndarray
    names: tuple[str, ...]


def state_estimate_layout(kind: str, names: Sequence[str]) -> MultiArrayLayout:
    """Return the layout of an estimate of the states `names` (see above)."""
    n = len(names)
    return MultiArrayLayout(
        dim=[MultiArrayDimension(label=kind, size=n + 1, stride=(n + 1) * n),
             MultiArrayDimension(label=','.join(names), size=n, stride=n)],
        data_offset=ESTIMATE_OFFSET)


def state_estimate_to_msg(kind: str, stamp_ns: int, mu: float, x: np.ndarray, P: np.ndarray,
                          names: Sequence[str]) -> Float64MultiArray:
    """Convert an estimate (x, P at stamp_ns, from a step of mu s) -> Float64MultiArray."""
    msg = Float64MultiArray(layout=state_estimate_layout(kind, names))
    return fill_state_estimate(msg, stamp_ns, mu, x, P)


def fill_state_estimate(msg: Float64MultiArray, stamp_ns: int, mu: float, x: np.ndarray,
                        P: np.ndarray) -> Float64MultiArray:
    """Fill the data of an estimate message in place (its layout kept); return it."""
    x = np.asarray(x, dtype=float).reshape(-1)
    n = x.size
    sec, nanosec = divmod(int(stamp_ns), NS)
    msg.data = [float(sec), float(nanosec), float(mu)] + x.tolist() + \
        np.asarray(P, dtype=float).reshape(n * n).tolist()
    return msg


def msg_to_state_estimate(msg: Float64MultiArray) -> StateEstimate:
    """Convert a Float64MultiArray of the layout above -> StateEstimate; ValueError if not."""
    dims, offset = msg.layout.dim, int(msg.layout.data_offset)
    data = np.asarray(msg.data, dtype=float)
    if len(dims) != 2 or offset != ESTIMATE_OFFSET:
        raise ValueError('not an estimate: its layout must have 2 dimensions and data_offset '
                         f'{ESTIMATE_OFFSET}')
    n = int(dims[1].size)
    if int(dims[0].size) != n + 1 or data.size != offset + n + n * n:
        raise ValueError(f'not an estimate: {data.size} entries for {n} states')
    names = tuple(dims[1].label.split(','))
    if len(names) != n:     # not the node's labels: no names
        names = ()
    stamp_ns = int(data[0]) * NS + int(data[1])
    return StateEstimate(dims[0].label, stamp_ns, float(data[2]), data[offset:offset + n],
                         data[offset + n:].reshape(n, n), names)


def diagnostics_to_msg(stamp_ns: int, node_name: str, statuses: Sequence[Status], *,
                       hardware_id: str = '') -> DiagnosticArray:
    """Build the DiagnosticArray of a node's tasks, each named '<node>: <task>'."""
    msg = DiagnosticArray(status=[
        DiagnosticStatus(level=bytes((s.level,)), name=f'{node_name}: {s.name}',
                         message=s.message, hardware_id=hardware_id,
                         values=[KeyValue(key=k, value=v) for k, v in s.values])
        for s in statuses])
    msg.header.stamp = ns_to_stamp(stamp_ns)
    return msg


def msg_to_diagnostics(msg: DiagnosticArray) -> dict:
    """Convert DiagnosticArray -> {status name: {key: value string, level, message}}."""
    out = {}
    for s in msg.status:
        values = {kv.key: kv.value for kv in s.values}
        values['level'] = int.from_bytes(s.level, 'little') if isinstance(s.level, bytes) \
            else int(s.level)
        values['message'] = s.message
        out[s.name] = values
    return out


# -- LED active alignment (Solanki et al.): tskf_ros.led.led_link, .alignment_session ------
#
# Angles in messages are radians (REP 103); the core and the parameters use the paper's
# degrees.  Types, all from common_interfaces:
#
# - intensity: sensor_msgs/msg/Illuminance as for the received power, illuminance = the
#   photodiode voltage V_d of eq. (5) in volts, variance = noise^2 in V^2.
# - base command: std_msgs/msg/Float64MultiArray with one entry, the base joint's absolute
#   position in rad: what a ros2_control forward_command_controller (position interface,
#   one joint) takes on <controller>/commands.
# - truth: sensor_msgs/msg/JointState with the joints LED_JOINTS (rad).
# - estimate: the estimate layout above, states ALIGNMENT_STATE_NAMES: x1 (V) and x2 (rad)
#   with their 2 x 2 covariance (V^2, V rad, rad^2).

LED_JOINTS = ('incidence', 'base', 'transmitter')


def _degree_scaling() -> np.ndarray:
    """Return diag(1, pi/180): [x1 V, x2 deg] -> [x1 V, x2 rad]."""
    return np.diag([1.0, np.pi / 180.0])


def intensity_to_msg(stamp_ns: int, volts: float, variance: float = 0.0, *,
                     frame_id: str = 'photodiode') -> Illuminance:
    """Convert (stamp, intensity V, variance V^2) -> Illuminance."""
    return power_to_msg(stamp_ns, volts, variance, frame_id=frame_id)


def msg_to_intensity(msg: Illuminance) -> tuple[int, float, float]:
    """Convert Illuminance -> (stamp ns, intensity V, variance V^2)."""
    return msg_to_power(msg)


def base_command_to_msg(angle_deg: float) -> Float64MultiArray:
    """Convert a base position command (deg) -> Float64MultiArray [rad]."""
    return Float64MultiArray(data=[float(np.deg2rad(angle_deg))])


def msg_to_base_command(msg: Float64MultiArray) -> np.ndarray:
    """Convert Float64MultiArray (rad, one entry per joint) -> angles in degrees."""
    return np.rad2deg(np.array(msg.data, dtype=float))


def led_truth_to_msg(stamp_ns: int, phi_deg: float, base_deg: float,
                     bearing_deg: float) -> JointState:
    """Convert (angle of incidence, base angle, transmitter bearing) deg -> JointState (rad)."""
    return angle_to_msg(stamp_ns, np.deg2rad([phi_deg, base_deg, bearing_deg]), LED_JOINTS)


def msg_to_led_truth(msg: JointState) -> tuple[int, dict]:
    """Convert JointState -> (stamp ns, {joint name: angle deg})."""
    stamp, positions = msg_to_angle(msg)
    return stamp, dict(zip(msg.name, np.rad2deg(positions)))


ALIGNMENT_STATE_NAMES = ('x1_intensity_V', 'x2_scan_mean_rad')


def alignment_state_to_msg(kind: str, stamp_ns: int, mu: float, x: np.ndarray,
                           P: np.ndarray) -> Float64MultiArray:
    """Convert EKF state [x1 V, x2 deg] and covariance (step of mu s) -> estimate layout (rad)."""
    D = _degree_scaling()
    return state_estimate_to_msg(kind, stamp_ns, mu, D @ np.asarray(x, dtype=float).reshape(2),
                                 D @ np.asarray(P, dtype=float).reshape(2, 2) @ D,
                                 ALIGNMENT_STATE_NAMES)


def msg_to_alignment_state(msg: Float64MultiArray) -> StateEstimate:
    """Convert an alignment estimate message -> StateEstimate with x2 in deg (P in V and deg)."""
    e = msg_to_state_estimate(msg)
    if e.x.size != 2:
        raise ValueError(f'not an alignment estimate: {e.x.size} states, not 2')
    Dinv = np.linalg.inv(_degree_scaling())
    return e._replace(x=Dinv @ e.x, P=Dinv @ e.P @ Dinv)


# -- input u of the time-scale estimator (EstimatorSession.add_input) ---------------------
#
# Type: geometry_msgs/msg/AccelStamped, header.stamp = the time from which u is held
# (zero-order hold until the next input), u[0..5] in accel.linear.x, .y, .z,
# accel.angular.x, .y, .z: six slots, u[i] in slot i; unused slots are 0 and ignored.
# Why this type: the inputs of the models we run are accelerations (the drogue's measured
# d'', a spring-mass force per unit mass), and AccelStamped is common_interfaces' stamped
# six-vector without extra semantics.  AccelWithCovarianceStamped would carry a covariance
# the filter does not use (u enters as known); WrenchStamped says force and torque;
# Imu forces orientation and angular velocity fields; std_msgs arrays have no stamp.
# A model with more than six input columns does not fit: the node passes all six slots
# and the session rejects the size ('input_size').

def input_to_msg(stamp_ns: int, u: Sequence[float], *,
                 frame_id: str = '') -> 'AccelStamped':
    """Convert (stamp, u of <= 6 entries) -> AccelStamped (slot i = u[i], the rest 0)."""
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.size > SLOTS:
        raise ValueError(f'an input of {u.size} > {SLOTS} entries does not fit the message')
    v = np.zeros(SLOTS)
    v[:u.size] = u
    from geometry_msgs.msg import AccelStamped
    msg = AccelStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    a = msg.accel
    a.linear.x, a.linear.y, a.linear.z = float(v[0]), float(v[1]), float(v[2])
    a.angular.x, a.angular.y, a.angular.z = float(v[3]), float(v[4]), float(v[5])
    return msg


def msg_to_input(msg: 'AccelStamped', m: int) -> tuple[int, np.ndarray]:
    """Convert AccelStamped -> (stamp ns, u): the first m slots (all six if m > 6)."""
    a = msg.accel
    v = np.array([a.linear.x, a.linear.y, a.linear.z, a.angular.x, a.angular.y, a.angular.z],
                 dtype=float)
    return stamp_to_ns(msg.header.stamp), v[:m] if m <= SLOTS else v
