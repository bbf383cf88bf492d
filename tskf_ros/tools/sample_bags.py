"""
make_sample_bags: generate the sample bags of bags/ deterministically from a seed.

    make_sample_bags --out bags --seed 2013            # all four
    make_sample_bags --out /tmp/b --only owc_cai_td_1hz

The bags hold what the drivers would publish (no estimates; `replay_offline` adds them):

- owc_cai_td_1hz: Cai et al.'s 300 s experiment at 1 Hz.  The power meter samples at
  every whole second; the received-power messages are exactly the whole seconds of Cai's
  T_d (tskf_ros.core.time_scales.CAI_TD_SEGMENTS realised at 1 s), i.e. t = 1..300 without the
  five interruptions 31, 127, 132-134, 210-211 and 219-223 (the jumps J = 2, 2, 4, 3, 6 of
  Fig. 6(b)).  The vibration amplitude is kept below 0.5 rad so that the power never
  drops to zero by itself: the only gaps are T_d's.  /true_angle has all 301 samples.
- owc_ge_1khz: one minute at 1 kHz through a Gilbert-Elliott channel (good -> bad 0.002,
  bad -> good 0.05 per sample: bursts of 20 ms on average, 3.8 % of the time blocked) on
  top of the vibration's own dropouts (readings at or below zero are not published).
- led_alignment: the scanning-EKF alignment of Solanki et al. (tskf_ros.led.simulate_tracking,
  Table I parameters, 400 steps of 50 ms, 5 % missing measurements), in the live alignment
  node's units (REP 103: angles in rad): the photodiode V_d on /photodiode, the truth on
  /alignment/truth (JointState LED_TRUTH: the angle of incidence phi and the scan mean x2
  in rad, and the intensity factor x1 in volts, not an angle), the EKF's estimate on
  /alignment/estimate as the node publishes it (conversions.alignment_estimate_to_msg: x1 in
  V, x2 in rad) and its command on /alignment/command as the node would send it
  (std_msgs/Float64MultiArray, one entry: the absolute base position in rad, i.e. the sum
  of the motor turns so far from base 0; not the node's base_position_controller/commands,
  which plot_bag takes for an alignment replay's output).
- drogue: Fang & de Callafon's drogue (tskf_ros.experiments.drogue.run with the seed, 4 h
  at T = 5 s): the position fixes at the surface on /received_power as the estimator's
  measurement (Illuminance used as a stamped scalar: displacement in m, variance
  gps_sd^2), the measured acceleration u on /input (geometry_msgs/AccelStamped, linear x:
  the estimator's input topic, held until the next sample) and the truth on
  /drogue/truth, every T.  At a stamp with a fix, the input is written first.

Stamps start at START_S (2023-11-14T22:13:20Z) plus the sample time; log time = stamp.
Messages are canonical CDR (tskf_ros.bag.cdr.serialize, rosbags' serializer): the same
message always gives the same bytes, and rosbags, mcap_ros2 and rclpy all read them.
Topics and types are listed in bags/README.md.
"""

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
from tskf_ros.messages import alignment_interface as aligner_interface
from tskf_ros.messages import conversions
from tskf_ros.owc.vibrating_link import OwcLink, OwcLinkConfig

PROG = 'make_sample_bags'
START_S = 1_700_000_000
DEFAULT_SEED = 2013
ILLUMINANCE = 'sensor_msgs/msg/Illuminance'
JOINT_STATE = 'sensor_msgs/msg/JointState'
ESTIMATE = 'geometry_msgs/msg/TwistWithCovarianceStamped'
ACCEL = 'geometry_msgs/msg/AccelStamped'
DROGUE_TRUTH = ('displacement_m', 'velocity_m_s', 'depth_m', 'flow_velocity_m_s')
# /alignment/truth of led_alignment: phi and x2 in rad, x1 in V
LED_TRUTH = ('incidence', 'scan_mean', 'intensity_factor')
SENSOR_QOS = [qos_from_rclpy(qos_profile_sensor_data)]
RELIABLE_QOS = [qos_from_rclpy(QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))]
# Gilbert-Elliott parameters of owc_ge_1khz
GE = {'ge_p_gb': 0.002, 'ge_p_bg': 0.05, 'ge_loss_good': 0.0, 'ge_loss_bad': 1.0}
LED_DROPOUT = 0.05


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
    """Cai's 300 s experiment at 1 Hz with the interruptions of T_d (see the module doc)."""
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
        writer.write('/alignment/estimate', stamp, serialize(
            conversions.alignment_estimate_to_msg(stamp, traj.estimate[k, 0],
                                                  aligner.P_history[k],
                                                  frame_id='scanning_ekf')))
        writer.write('/alignment/command', stamp, serialize(
            conversions.base_command_to_msg(base[k])))


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
           'led_alignment': led_alignment, 'drogue': drogue}


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
    console_main()
