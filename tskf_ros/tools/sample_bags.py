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

"""make_sample_bags: the sample bags of bags/, generated deterministically from a seed."""

import argparse
from pathlib import Path
import sys
from typing import Callable, Optional

import numpy as np
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy

from tskf_ros import led
from tskf_ros.bag.cdr import serialize
from tskf_ros.bag.message_types import qos_from_rclpy
from tskf_ros.bag.reader import error_exit
from tskf_ros.bag.writer import BagError, BagWriter
from tskf_ros.core.time_scales import cai_td
from tskf_ros.core.units import NS
from tskf_ros.experiments import drogue as drogue_sim
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_session import (pan_tilt_closed_loop, PanTiltSession,
                                                    PanTiltSessionConfig)
from tskf_ros.messages import alignment_interface as aligner_interface
from tskf_ros.messages import conversions
from tskf_ros.messages.pan_tilt_messages import (pan_tilt_command_to_msg, pan_tilt_state_to_msg,
                                                 pan_tilt_truth_to_msg)
from tskf_ros.owc.vibrating_link import OwcLink, OwcLinkConfig

PROG = 'make_sample_bags'
START_S = 1_700_000_000
DEFAULT_SEED = 2013
ILLUMINANCE = 'sensor_msgs/msg/Illuminance'
JOINT_STATE = 'sensor_msgs/msg/JointState'
ESTIMATE = aligner_interface.ESTIMATE_TYPE
ACCEL = 'geometry_msgs/msg/AccelStamped'
DROGUE_TRUTH = ('displacement_m', 'velocity_m_s', 'depth_m', 'flow_velocity_m_s')
# /alignment/truth of led_alignment: phi and x2 in rad, x1 in V
LED_TRUTH = ('incidence', 'scan_mean', 'intensity_factor')
SENSOR_QOS = [qos_from_rclpy(qos_profile_sensor_data)]
RELIABLE_QOS = [qos_from_rclpy(QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))]
# Gilbert-Elliott parameters of owc_ge_1khz
GE = {'ge_p_gb': 0.002, 'ge_p_bg': 0.05, 'ge_loss_good': 0.0, 'ge_loss_bad': 1.0}
LED_DROPOUT = 0.05
# led_pan_tilt: 20 s at 50 ms, the default joint names
PAN_TILT_STEPS = 400
PAN_TILT_JOINTS = ('pan', 'tilt')


def td_seconds() -> np.ndarray:
    """Return the whole seconds of Cai's T_d (its points realised at a 1 s step)."""
    points = np.asarray(cai_td(1.0).points, dtype=float)
    return np.unique(np.round(points).astype(int))


def _owc(writer: BagWriter, link: OwcLinkConfig, n: int,
         keep: Callable[[np.ndarray], np.ndarray]) -> None:
    """Write n link samples: the truth always, the power where keep() and not blocked."""
    writer.add_topic('/received_power', ILLUMINANCE, qos=SENSOR_QOS)
    writer.add_topic('/true_angle', JOINT_STATE, qos=RELIABLE_QOS)
    s = OwcLink(link).generate(n)
    publish = keep(s.index) & ~s.blocked & (s.reading > 0)
    var = link.noise_std ** 2
    for i in range(n):
        stamp = START_S * NS + int(round(int(s.index[i]) * NS / link.rate))
        writer.write('/true_angle', stamp, serialize(
            conversions.angle_to_msg(stamp, [s.theta[i]], ['theta'])))
        if publish[i]:
            writer.write('/received_power', stamp, serialize(
                conversions.power_to_msg(stamp, s.reading[i], var)))


def owc_cai_td_1hz(writer: BagWriter, seed: int) -> None:
    """Cai's 300 s experiment at 1 Hz with the interruptions of T_d (doc/design/nodes.md)."""
    link = OwcLinkConfig(rate=1.0, seed=seed, knob_max=0.5, knob_initial=0.3)
    td = set(td_seconds().tolist())
    _owc(writer, link, 301, lambda k: np.isin(k, list(td)))


def owc_ge_1khz(writer: BagWriter, seed: int) -> None:
    """One minute at 1 kHz through a Gilbert-Elliott channel."""
    link = OwcLinkConfig(rate=1000.0, seed=seed, blockage='gilbert_elliott', **GE)
    _owc(writer, link, 60_000, lambda k: np.ones(k.shape, dtype=bool))


class _RecordingEKF(led.ScanningEKF):
    """The scanning EKF that also keeps its posterior covariance after every step."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.P_history: list = []

    def step(self, stamp: float, z: led.Measurement) -> np.ndarray:
        cmd = super().step(stamp, z)
        self.P_history.append(self.P[0].copy())
        return cmd


def led_alignment(writer: BagWriter, seed: int) -> None:
    """Simulate one scanning-EKF alignment run of Solanki et al. Section V."""
    aligner = _RecordingEKF(led.EKFConfig(), runs=1)
    link = led.TrackingLinkConfig(dropout=LED_DROPOUT)
    traj = led.simulate_tracking(aligner, link, np.random.default_rng(seed))
    writer.add_topic('/photodiode', ILLUMINANCE, qos=SENSOR_QOS)
    writer.add_topic('/alignment/truth', JOINT_STATE, qos=RELIABLE_QOS)
    writer.add_topic('/alignment/estimate', ESTIMATE, qos=RELIABLE_QOS)
    writer.add_topic('/alignment/command', aligner_interface.COMMAND_TYPE, qos=RELIABLE_QOS)
    var = link.noise ** 2
    base = np.cumsum(traj.command[:, 0])     # deg: the absolute base, from 0
    for k, t in enumerate(traj.t):
        stamp = START_S * NS + int(round(t * NS))
        truth = [np.deg2rad(traj.phi[k, 0]), np.deg2rad(traj.x2[k, 0]), traj.x1[k, 0]]
        writer.write('/alignment/truth', stamp, serialize(
            conversions.angle_to_msg(stamp, truth, LED_TRUTH)))
        z = traj.z[k, 0]
        if np.isfinite(z):
            writer.write('/photodiode', stamp, serialize(
                conversions.power_to_msg(stamp, z, var, frame_id='photodiode')))
        # the corrected estimate from the step into t_k: mu = dt (0 at the first sample)
        writer.write('/alignment/estimate', stamp, serialize(
            conversions.alignment_state_to_msg('corrected', stamp, link.dt if k else 0.0,
                                               traj.estimate[k, 0], aligner.P_history[k])))
        writer.write('/alignment/command', stamp, serialize(
            conversions.base_command_to_msg(base[k])))


def led_pan_tilt(writer: BagWriter, seed: int) -> None:
    """Simulate one two-axis run: the conical-scan EKF on a pan-tilt mount, as the nodes run it."""
    link = PanTiltLinkConfig(dropout=LED_DROPOUT)
    session = PanTiltSession(PanTiltSessionConfig(noise=link.noise))
    run = pan_tilt_closed_loop(link, session, PAN_TILT_STEPS, seed=seed,
                               start_ns=START_S * NS)
    writer.add_topic('/photodiode', ILLUMINANCE, qos=SENSOR_QOS)
    writer.add_topic('/pan_tilt/truth', JOINT_STATE, qos=RELIABLE_QOS)
    writer.add_topic('/pan_tilt/estimate', ESTIMATE, qos=RELIABLE_QOS)
    writer.add_topic('/pan_tilt/command', aligner_interface.COMMAND_TYPE, qos=RELIABLE_QOS)
    last = None
    for s, out in zip(run.samples, run.outcomes):
        stamp = START_S * NS + int(round(s.t * NS))
        writer.write('/pan_tilt/truth', stamp, serialize(pan_tilt_truth_to_msg(
            stamp, s.joints[0], s.source[0], float(s.theta[0]), PAN_TILT_JOINTS)))
        if out is None:         # dropped: never reached the receiver
            continue
        writer.write('/photodiode', stamp, serialize(
            conversions.power_to_msg(stamp, float(s.reading[0]), link.noise ** 2,
                                     frame_id='photodiode')))
        if out.estimate is not None:
            mu = 0.0 if last is None else (stamp - last) / NS
            e = out.estimate
            writer.write('/pan_tilt/estimate', stamp, serialize(pan_tilt_state_to_msg(
                'corrected', stamp, mu, e.x, e.P, e.states)))
        if out.command is not None:
            writer.write('/pan_tilt/command', stamp, serialize(
                pan_tilt_command_to_msg(out.command, PAN_TILT_JOINTS)))
        last = stamp


def drogue(writer: BagWriter, seed: int) -> None:
    """Simulate one drogue of Fang & de Callafon Section IV (tskf_ros.experiments.drogue)."""
    run = drogue_sim.run(drogue_sim.DrogueConfig(seed=seed))
    cfg, truth = run.cfg, run.truth
    writer.add_topic('/received_power', ILLUMINANCE, qos=SENSOR_QOS)
    writer.add_topic('/input', ACCEL, qos=SENSOR_QOS)
    writer.add_topic('/drogue/truth', JOINT_STATE, qos=RELIABLE_QOS)
    for k, t in enumerate(truth.t):
        stamp = START_S * NS + int(round(t * NS))
        values = [truth.x[k, 0], truth.x[k, 1], truth.z[k], truth.v_flow[k]]
        writer.write('/drogue/truth', stamp, serialize(
            conversions.angle_to_msg(stamp, values, DROGUE_TRUTH)))
        writer.write('/input', stamp, serialize(
            conversions.input_to_msg(stamp, [run.u[k]], frame_id='drogue')))
        if truth.gamma[k]:
            writer.write('/received_power', stamp, serialize(conversions.power_to_msg(
                stamp, run.y[k, 0], cfg.gps_sd ** 2, frame_id='drogue_gps')))


SAMPLES = {'owc_cai_td_1hz': owc_cai_td_1hz, 'owc_ge_1khz': owc_ge_1khz,
           'led_alignment': led_alignment, 'led_pan_tilt': led_pan_tilt, 'drogue': drogue}


def make(name: str, out: Path, seed: int = DEFAULT_SEED, *, overwrite: bool = False) -> Path:
    """Generate one sample bag as out/name (zstd-compressed MCAP); return its path."""
    with BagWriter(Path(out) / name, overwrite=overwrite, compress=True) as writer:
        SAMPLES[name](writer, seed)
    return Path(out) / name


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(prog=PROG, description='Generate the sample bags.')
    parser.add_argument('--out', type=Path, default=Path('bags'), help='directory (bags)')
    parser.add_argument('--seed', type=int, default=DEFAULT_SEED)
    parser.add_argument('--only', choices=sorted(SAMPLES), action='append',
                        help='generate only this bag (repeatable)')
    parser.add_argument('--overwrite', action='store_true', help='replace existing bags')
    args = parser.parse_args(argv)
    if not 0 <= args.seed < 2 ** 32:
        parser.error(f'--seed must be in [0, 2**32), got {args.seed}')
    names = list(dict.fromkeys(args.only or SAMPLES))
    try:     # every target is checked before any bag is made
        for name in names:
            BagWriter(args.out / name, overwrite=args.overwrite).check_target()
    except BagError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 1
    for name in names:
        try:
            path = make(name, args.out, args.seed, overwrite=args.overwrite)
        except (BagError, OSError) as exc:
            return error_exit(PROG, exc, args.out)
        size = sum(f.stat().st_size for f in path.iterdir())
        print(f'{PROG}: wrote {path} ({size / 1e6:.2f} MB, seed {args.seed})')
    return 0


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
