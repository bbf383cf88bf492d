"""
alignment: LED active alignment (Solanki et al.) on a stream of stamped intensity samples.

Subscribes to `intensity` (sensor_msgs/msg/Illuminance, volts, best effort so that both
reliable and best-effort publishers match), feeds tskf_ros.alignment.AlignmentSession,
and publishes for every sample it uses: the base position command on
`base_position_controller/commands` (std_msgs/msg/Float64MultiArray, one entry in rad,
as a ros2_control forward_command_controller takes it) and, with the EKF, the estimate
[x1, x2] before and after the update on `estimate/predicted` and `estimate/corrected`
(geometry_msgs/msg/TwistWithCovarianceStamped); see tskf_ros.nodes.conversions.  Counters
go to /diagnostics.

The offline replay (tskf_ros.bag.alignment_io) publishes the same messages through this
module's `default_parameters`, `outcome_messages`, `diagnostics_message`, `OUTPUT_TOPICS`
and `output_qos`, so live and offline replay cannot drift apart.
"""

from dataclasses import dataclass, fields
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistWithCovarianceStamped
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.clock import ClockChange, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Illuminance
from std_msgs.msg import Float64MultiArray

from tskf_ros import led
from tskf_ros.alignment import AlignmentConfig, AlignmentSession, AlignOutcome
from tskf_ros.nodes import conversions
from tskf_ros.nodes.common import ReconfigurableNode, run_node, sensor_input_qos

NODE_NAME = 'alignment'
INPUT_TOPIC = 'intensity'
COMMAND_TOPIC = 'base_position_controller/commands'
# output -> topic (relative: resolved in the node's namespace), in publishing order
OUTPUT_TOPICS = {
    'predicted': 'estimate/predicted',
    'corrected': 'estimate/corrected',
    'command': COMMAND_TOPIC,
}
D, DA = ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_DOUBLE_ARRAY
B = ParameterType.PARAMETER_BOOL
# AlignmentConfig field -> (type, description, (lo, hi) or None, read_only)
SESSION_PARAMETERS = {
    'algorithm': (ParameterType.PARAMETER_STRING, 'ekf (the scanning EKF of Section IV), '
                  'hill_climbing or three_point (the baselines of Section V)', None, False),
    'dt': (D, 's: nominal sample period; the EKF predicts over mu = elapsed / dt steps',
           (1e-6, 3600.0), False),
    'gain': (D, 'G of the P controller u = -G x2hat (21); needs G > 1/91 for 2 deg scan '
             'steps (observability, eq. (24)) and G < 2', None, False),
    'x0': (DA, 'initial estimate [x1 (V), x2 (deg)] (Table I: [2, 0])', None, False),
    'P0': (DA, 'initial covariance, 2 x 2 row-major (Table I: diag(100, 1000))', None, False),
    'Q': (DA, 'EKF process noise per dt, 2 x 2 row-major (Table I: diag(0.25, 1))', None,
          False),
    'R': (DA, 'EKF measurement noise of a pair, 2 x 2 row-major (Table I: diag(1, 1))',
          None, False),
    'scan': (DA, 'deg: the scan set Psi, visited cyclically (Section IV: +-10 in 2 steps)',
             None, False),
    'x1_floor': (D, 'V: keep x1hat at least this (Section IV assumes x1 > 0); 0: off, '
                 'as in the paper', (0.0, 1e6), False),
    'gamma': (D, 'deg: step of hill-climbing and three-point averaging (Section V: 2)',
              (1e-6, 180.0), False),
    'clip': (B, 'three-point: gamma_p = 0 if V1 + V2 + V3 <= 0, clipped to +-gamma '
             '(not in the paper)', None, False),
    'units_per_degree': (D, 'fit units of g (eq. (4)) per degree; 0: the unit for which '
                         '+-15 deg is 20% of the peak (17.7)', (0.0, 1e4), False),
    'base_initial': (D, 'deg: the base angle when the node starts (commands are absolute)',
                     (-1e6, 1e6), True),
    'negative_is_missing': (B, 'a negative intensity is a missing sample (true), or used as '
                            'it is (false: the paper simulation)', None, False),
    'max_gap': (D, 's: a longer gap between samples sets the diagnostics level to WARN',
                (0.0, 1e6), False),
    'max_backward': (D, 's: a stamp further behind the last restarts the aligner (clock '
                     'reset, looped bag); closer: dropped as stale', (0.0, 1e6), False),
}
PARAMETERS = tuple(SESSION_PARAMETERS) + ('frame_id', 'diagnostics_period', 'queue_depth')


@dataclass(frozen=True)
class NodeConfig:
    """The node's own settings, read once; the session's are in `session`."""

    session: AlignmentConfig
    frame_id: str
    diagnostics_period: float
    queue_depth: int


def parameters_to_config(values: dict) -> NodeConfig:
    """Build the config from parameter values; raise AlignmentError with the reason if bad."""
    kwargs = {}
    for f in fields(AlignmentConfig):
        v = values[f.name]
        if SESSION_PARAMETERS[f.name][0] == DA:
            if isinstance(v, (str, bytes)) or any(isinstance(e, (bool, str)) for e in v):
                raise led.AlignmentError(f'{f.name} must be a list of numbers, got {v!r}')
            v = tuple(float(e) for e in v)
        kwargs[f.name] = v
    return NodeConfig(AlignmentConfig(**kwargs), values['frame_id'],
                      values['diagnostics_period'], values['queue_depth'])


def default_parameters() -> dict:
    """Return the declared default of every parameter (Table I of Solanki et al.)."""
    defaults = AlignmentConfig()
    values = {}
    for name, (type_, _, _, _) in SESSION_PARAMETERS.items():
        value = getattr(defaults, name)
        values[name] = [float(v) for v in value] if type_ == DA else value
    values.update({'frame_id': 'receiver', 'diagnostics_period': 1.0, 'queue_depth': 100})
    return values


def output_qos(config: NodeConfig, output: str) -> QoSProfile:
    """
    Return the QoS of an output's publisher: reliable, keep last.

    The command keeps the system default depth 10 (what forward_command_controller
    subscribes with); the estimates keep queue_depth.
    """
    depth = 10 if output == 'command' else config.queue_depth
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE)


def outcome_messages(out: AlignOutcome, config: NodeConfig) -> list:
    """Return the (output, message) pairs to publish for an outcome, in order."""
    if out.command is None:
        return []
    msgs = []
    if out.prior is not None:
        msgs.append(('predicted', conversions.alignment_estimate_to_msg(
            out.stamp_ns, *out.prior, frame_id=config.frame_id)))
        msgs.append(('corrected', conversions.alignment_estimate_to_msg(
            out.stamp_ns, *out.posterior, frame_id=config.frame_id)))
    msgs.append(('command', conversions.base_command_to_msg(out.command)))
    return msgs


def diagnostics_message(session: AlignmentSession, config: NodeConfig, stamp_ns: int, *,
                        node_name: str = NODE_NAME) -> DiagnosticArray:
    """Return the /diagnostics message of the session's counters at stamp_ns."""
    level, message, values = session.diagnostics()
    return conversions.diagnostics_to_msg(stamp_ns, f'{node_name}: LED alignment', level,
                                          message, values, hardware_id=config.frame_id)


class Alignment(ReconfigurableNode):
    """Node wrapping AlignmentSession: intensity in, base commands, estimates, diagnostics out."""

    PARAMETERS = PARAMETERS
    CONFIG_ERRORS = (led.AlignmentError, KeyError, TypeError, ValueError)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self._declare()
        self.config = self.start_watching_parameters()
        self.session = AlignmentSession(self.config.session)

        qos_in = sensor_input_qos(self.config.queue_depth)
        self.sub = self.create_subscription(Illuminance, INPUT_TOPIC, self._on_intensity,
                                            qos_in)
        self.pubs = {
            key: self.create_publisher(
                Float64MultiArray if key == 'command' else TwistWithCovarianceStamped, topic,
                output_qos(self.config, key))
            for key, topic in OUTPUT_TOPICS.items()}
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.diag_timer = self.create_timer(self.config.diagnostics_period,
                                            self.publish_diagnostics)
        # use_sim_time: a clock that jumps back (a looped bag) or changes source restarts
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1_000_000),
                          on_clock_change=True),
            post_callback=self._on_clock_jump)
        cfg = self.config.session
        self.get_logger().info(
            f'aligning with {cfg.algorithm}'
            + (f' (G = {cfg.gain:g}, {len(cfg.scan)} scan angles)'
               if cfg.algorithm == 'ekf' else f' (gamma = {cfg.gamma:g} deg)')
            + f', base starting at {cfg.base_initial:g} deg')

    # -- parameters -----------------------------------------------------------------------

    def _declare(self) -> None:
        defaults = default_parameters()
        for name, (type_, text, rng, read_only) in SESSION_PARAMETERS.items():
            value = defaults[name]
            d = ParameterDescriptor(description=text, type=type_, read_only=read_only)
            if rng is not None:
                d.floating_point_range = [FloatingPointRange(from_value=rng[0],
                                                             to_value=rng[1])]
            if name == 'algorithm':
                d.additional_constraints = 'one of ' + ', '.join(led.ALGORITHMS)
            self.declare_parameter(name, value, d)
        self.declare_parameter('frame_id', defaults['frame_id'], ParameterDescriptor(
            description='frame_id of the estimates', type=ParameterType.PARAMETER_STRING))
        self.declare_parameter('diagnostics_period', defaults['diagnostics_period'],
                               ParameterDescriptor(
                                   description='seconds between /diagnostics messages', type=D,
                                   floating_point_range=[FloatingPointRange(
                                       from_value=0.01, to_value=3600.0)]))
        self.declare_parameter('queue_depth', defaults['queue_depth'], ParameterDescriptor(
            description='depth of the input and estimate queues', read_only=True,
            type=ParameterType.PARAMETER_INTEGER,
            integer_range=[IntegerRange(from_value=1, to_value=100_000)]))

    def make_config(self, values: dict) -> NodeConfig:
        """Build the node's config; raises with the reason if it makes no working aligner."""
        return parameters_to_config(values)

    def reconfigure(self, config: NodeConfig) -> str:
        """Switch the session to a validated config; return what it did."""
        return self.session.reconfigure(config.session)

    # -- data -----------------------------------------------------------------------------

    def _on_intensity(self, msg: Illuminance) -> None:
        stamp_ns, volts, _ = conversions.msg_to_intensity(msg)
        out = self.session.add(stamp_ns, volts)
        self._report(out)
        self._publish(out)

    def _report(self, out: AlignOutcome) -> None:
        log = self.get_logger()
        if out.status == 'rejected':
            log.warning(f'sample dropped ({out.reason}): {out.message}')
        elif out.status == 'missing':
            log.warning(f'sample at {out.stamp_ns / 1e9:.3f} s treated as missing '
                        f'({out.reason}): {out.message}', throttle_duration_sec=1.0)
        elif out.status == 'reset':
            log.warning(f'aligner restarted ({out.reason}): {out.message}')

    def _publish(self, out: AlignOutcome) -> None:
        for key, msg in outcome_messages(out, self.config):
            self.pubs[key].publish(msg)

    def _on_clock_jump(self, jump: TimeJump) -> None:
        if self.session.last_ns is None:
            return
        if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED,
                                 ClockChange.ROS_TIME_DEACTIVATED):
            why = f'clock source changed ({jump.clock_change.name})'
        else:
            why = f'clock jumped {jump.delta.nanoseconds / 1e9:.3f} s'
        self.session.reset('clock_jump')
        self.get_logger().warning(f'aligner restarted: {why}')

    def publish_diagnostics(self) -> DiagnosticArray:
        """Publish (and return) the session's counters on /diagnostics."""
        msg = diagnostics_message(self.session, self.config,
                                  self.get_clock().now().nanoseconds,
                                  node_name=self.get_name())
        self.diag_pub.publish(msg)
        return msg


DESCRIPTION = ('LED active alignment (Solanki et al.): scanning EKF, hill-climbing or '
               'three-point averaging on the intensity, commanding a rotating base. '
               'Parameters: --ros-args --params-file config/alignment.yaml or -p name:=value')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(Alignment, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(led.AlignmentError,), args=args)


if __name__ == '__main__':
    main()
