"""
timescale_estimator: the time-scale Kalman filter on a stream of received-power samples.

Subscribes to `received_power` (sensor_msgs/msg/Illuminance, best effort so that both
reliable and best-effort publishers match), feeds tskf_ros.estimation.EstimatorSession,
and publishes what the session returns; see tskf_ros.nodes.conversions for the types.
The model's input u comes on `input` (geometry_msgs/msg/AccelStamped, slot i = u[i],
held from its stamp to the next input; best effort too); a model without B counts such
messages as rejected ('no_input_matrix') and ignores them.
"""

from dataclasses import dataclass
from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistWithCovarianceStamped
import numpy as np
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor, ParameterType
from rclpy.clock import ClockChange, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Illuminance, TimeReference

from tskf_ros.estimation import (ConfigError, EstimatorConfig, EstimatorSession,
                                 model_from_flat, Outcome)
from tskf_ros.models import owc
from tskf_ros.nodes import conversions
from tskf_ros.nodes.common import (float_range, ReconfigurableNode, run_node,
                                   sensor_input_qos)
from tskf_ros.tskf import FilterError, TRANSITIONS

NODE_NAME = 'timescale_estimator'
MATRICES = ('A', 'B', 'C', 'D', 'G', 'Q', 'R', 'x0', 'P0')
MATRIX_HELP = {
    'A': 'x^Delta = A x + B u + G w: A, n x n row-major (model (3): [1.0])',
    'B': 'input matrix, n x m row-major (u on the input topic, m <= 6); empty for none',
    'C': 'y = C x + D + v: C, p x n row-major (model (3): [-637.35])',
    'D': 'output offset, p entries; empty for 0 (model (3): [511.97])',
    'G': 'process noise input, n x r row-major; empty for identity',
    'Q': 'process noise intensity, r x r, symmetric positive semi-definite',
    'R': 'measurement noise intensity, p x p, symmetric positive definite',
    'x0': 'initial estimate, n entries',
    'P0': 'initial covariance, n x n, symmetric positive semi-definite',
}
# name -> (default, description, (lo, hi))
SCALARS = {
    'period': (1.0, 'nominal sample period (s): sorts intervals into dense, discrete and '
               'jumps (Cai IV-C)', (1e-6, 3600.0)),
    'dense_fraction': (0.5, 'an interval shorter than dense_fraction * period is dense',
                       (0.0, 1.0)),
    'jump_factor': (1.5, 'an interval longer than jump_factor * period is a gap (a jump J)',
                    (1.0, 1000.0)),
    'max_gap': (5.0, 'a gap longer than this (s) sets the diagnostics level to WARN',
                (0.0, 1e6)),
    'history_window': (10.0, 'a late sample at most this much (s) older than the newest is '
                       'inserted and the filter re-run', (0.0, 3600.0)),
    'max_jump': (60.0, 'a stamp further ahead (s) of the last point re-initialises the '
                 'filter', (1e-6, 1e6)),
    'max_backward': (30.0, 'a stamp further behind (s) the last point re-initialises the '
                     'filter (clock reset, looped bag); >= history_window', (0.0, 1e6)),
    'max_future': (0.0, "a stamp further ahead (s) of this node's clock is rejected; 0: "
                   'off (replayed or time-compressed streams)', (0.0, 1e6)),
    'diagnostics_period': (1.0, 'seconds between /diagnostics messages', (0.01, 3600.0)),
}
PARAMETERS = MATRICES + tuple(SCALARS) + (
    'model_name', 'state_names', 'transition', 'history_size', 'queue_depth', 'frame_id',
    'nonpositive_is_gap')


@dataclass(frozen=True)
class NodeConfig:
    """The node's own settings, read once; the filter's are in `estimator`."""

    estimator: EstimatorConfig
    frame_id: str
    diagnostics_period: float
    queue_depth: int


def parameters_to_config(values: dict) -> NodeConfig:
    """Build the config from parameter values; raise ConfigError with the reason if bad."""
    flat = {}
    for key in MATRICES:
        v = values[key]
        if isinstance(v, (str, bytes)) or any(isinstance(e, (bool, str)) for e in v):
            raise ConfigError(f'{key} must be a list of numbers, got {v!r}')
        flat[key] = [float(e) for e in v]
    model = model_from_flat(name=values['model_name'],
                            state_names=tuple(values['state_names']), **flat)
    estimator = EstimatorConfig(
        model, transition=values['transition'], period=values['period'],
        dense_fraction=values['dense_fraction'], jump_factor=values['jump_factor'],
        max_gap=values['max_gap'], history_window=values['history_window'],
        history_size=values['history_size'], max_jump=values['max_jump'],
        max_backward=values['max_backward'], max_future=values['max_future'],
        nonpositive_is_gap=values['nonpositive_is_gap'])
    return NodeConfig(estimator, values['frame_id'], values['diagnostics_period'],
                      values['queue_depth'])


INPUT_TOPIC = 'input'
# (estimate kind, revised) -> output topic
OUTPUT_TOPICS = {
    ('predicted', False): 'estimate/predicted',
    ('corrected', False): 'estimate/corrected',
    ('mu', False): 'estimate/mu',
    ('predicted', True): 'estimate/revised/predicted',
    ('corrected', True): 'estimate/revised/corrected',
    ('mu', True): 'estimate/revised/mu',
}


def default_parameters() -> dict:
    """Return the declared default of every parameter (the OWC model (3) of Cai et al.)."""
    d = owc()
    matrices = {'A': d.A, 'B': (), 'C': d.C, 'D': d.D, 'G': d.G, 'Q': d.Q, 'R': d.R,
                'x0': d.x0, 'P0': d.P0}
    values: dict = {key: [float(v) for v in np.ravel(matrices[key])] for key in MATRICES}
    values.update({name: spec[0] for name, spec in SCALARS.items()})
    values.update({'model_name': d.name, 'state_names': list(d.state_names),
                   'transition': 'euler', 'history_size': 1000, 'queue_depth': 100,
                   'nonpositive_is_gap': True, 'frame_id': ''})
    return values


def output_qos(config: NodeConfig) -> QoSProfile:
    """Return the QoS of the estimate publishers: reliable, keep last queue_depth."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=config.queue_depth,
                      reliability=ReliabilityPolicy.RELIABLE)


def outcome_messages(out: Outcome, config: NodeConfig) -> list:
    """Return the ((kind, revised), message) pairs to publish for an Outcome, in order."""
    frame = config.frame_id or config.estimator.model.name
    msgs = [((e.kind, e.revised),
             conversions.estimate_to_msg(e.stamp_ns, e.x, e.P, frame_id=frame))
            for e in out.estimates]
    msgs += [(('mu', j.revised), conversions.jump_to_msg(j.stamp_ns, j.sigma_ns))
             for j in out.jumps]
    return msgs


def input_from_msg(msg: AccelStamped, session: EstimatorSession) -> tuple:
    """Return (stamp ns, u) of an input message for the session's model (B's columns)."""
    return conversions.msg_to_input(msg, session.u.size)


class TimescaleEstimator(ReconfigurableNode):
    """Node wrapping EstimatorSession: received power in, estimates and diagnostics out."""

    PARAMETERS = PARAMETERS
    CONFIG_ERRORS = (ConfigError, FilterError, KeyError, TypeError, ValueError)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self._declare()
        self.config = self.start_watching_parameters()
        self.session = EstimatorSession(self.config.estimator)

        qos_in = sensor_input_qos(self.config.queue_depth)
        self.sub = self.create_subscription(Illuminance, 'received_power', self._on_power,
                                            qos_in)
        self.input_sub = self.create_subscription(AccelStamped, INPUT_TOPIC, self._on_input,
                                                  qos_in)
        qos_out = output_qos(self.config)
        self.pubs = {
            key: self.create_publisher(
                TimeReference if key[0] == 'mu' else TwistWithCovarianceStamped, topic, qos_out)
            for key, topic in OUTPUT_TOPICS.items()}
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.diag_timer = self.create_timer(self.config.diagnostics_period,
                                            self.publish_diagnostics)
        # use_sim_time: a clock that jumps back (a looped bag) or changes source restarts
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1_000_000),
                          on_clock_change=True),
            post_callback=self._on_clock_jump)
        m = self.config.estimator.model
        self.get_logger().info(
            f'estimating {m.name} (n = {m.A.shape[0]}, states {", ".join(m.state_names)}) '
            f'with the {self.config.estimator.transition} transition')

    # -- parameters -----------------------------------------------------------------------

    def _declare(self) -> None:
        defaults = default_parameters()
        for key in MATRICES:
            self.declare_parameter(key, defaults[key], ParameterDescriptor(
                description=MATRIX_HELP[key], dynamic_typing=True))
        self.declare_parameter('model_name', defaults['model_name'], ParameterDescriptor(
            description="name of the model, used as the estimates' frame_id if that is empty",
            type=ParameterType.PARAMETER_STRING))
        self.declare_parameter('state_names', defaults['state_names'], ParameterDescriptor(
            description='one name per state; the order of the estimate message slots',
            type=ParameterType.PARAMETER_STRING_ARRAY))
        self.declare_parameter('transition', defaults['transition'], ParameterDescriptor(
            description="how a jump mu is discretised: euler = the paper's I + mu A; "
            'exact = expm(A mu) with Van Loan process noise',
            additional_constraints='one of ' + ', '.join(TRANSITIONS),
            type=ParameterType.PARAMETER_STRING))
        for name, (_, text, (lo, hi)) in SCALARS.items():
            self.declare_parameter(name, defaults[name], ParameterDescriptor(
                description=text, type=ParameterType.PARAMETER_DOUBLE, **float_range(lo, hi)))
        self.declare_parameter('history_size', defaults['history_size'], ParameterDescriptor(
            description='points (and filter states) kept for rewinding on a late sample',
            type=ParameterType.PARAMETER_INTEGER,
            integer_range=[IntegerRange(from_value=2, to_value=1_000_000)]))
        self.declare_parameter('queue_depth', defaults['queue_depth'], ParameterDescriptor(
            description='depth of the input and output queues', read_only=True,
            type=ParameterType.PARAMETER_INTEGER,
            integer_range=[IntegerRange(from_value=1, to_value=100_000)]))
        gap_help = ('a measurement <= 0 is an invalid reading, a gap (Cai IV-C: power); '
                    'false for models whose output may be negative')
        self.declare_parameter('nonpositive_is_gap', defaults['nonpositive_is_gap'],
                               ParameterDescriptor(description=gap_help,
                                                   type=ParameterType.PARAMETER_BOOL))
        self.declare_parameter('frame_id', defaults['frame_id'], ParameterDescriptor(
            description='frame_id of the estimates (empty: model_name)',
            type=ParameterType.PARAMETER_STRING))

    def make_config(self, values: dict) -> NodeConfig:
        """Build the node's config; raises with the reason if it makes no working filter."""
        return parameters_to_config(values)

    def reconfigure(self, config: NodeConfig) -> str:
        """Switch the session to a validated config; return what it did."""
        return self.session.reconfigure(config.estimator).message

    # -- data -----------------------------------------------------------------------------

    def _on_power(self, msg: Illuminance) -> None:
        stamp_ns, power, variance = conversions.msg_to_power(msg)
        out = self.session.add(stamp_ns, power, variance,
                               now_ns=self.get_clock().now().nanoseconds)
        self._report(out)
        self._publish(out)

    def _on_input(self, msg: AccelStamped) -> None:
        out = self.session.add_input(*input_from_msg(msg, self.session))
        self._report(out)
        self._publish(out)

    def _report(self, out: Outcome) -> None:
        log = self.get_logger()
        if out.status == 'rejected':
            log.warning(f'sample rejected ({out.reason}): {out.message}')
        elif out.status == 'reset':
            log.warning(f'filter re-initialised ({out.reason}): {out.message}')
        elif out.status == 'inserted':
            log.info(out.message)
        elif out.status == 'gap':
            log.debug(out.message)

    def _publish(self, out: Outcome) -> None:
        for key, msg in outcome_messages(out, self.config):
            self.pubs[key].publish(msg)

    def _on_clock_jump(self, jump: TimeJump) -> None:
        if self.session.pending() is None:
            return
        if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED,
                                 ClockChange.ROS_TIME_DEACTIVATED):
            why = f'clock source changed ({jump.clock_change.name})'
        else:
            why = f'clock jumped {jump.delta.nanoseconds / 1e9:.3f} s'
        out = self.session.reset('clock_jump', why)
        self.get_logger().warning(f'filter re-initialised: {out.message}')

    def publish_diagnostics(self) -> DiagnosticArray:
        """Publish (and return) the session's counters on /diagnostics."""
        level, message, values = self.session.diagnostics()
        msg = conversions.diagnostics_to_msg(
            self.get_clock().now().nanoseconds, f'{self.get_name()}: time-scale filter',
            level, message, values, hardware_id=self.config.estimator.model.name)
        self.diag_pub.publish(msg)
        return msg


DESCRIPTION = ('Time-scale Kalman filter on received power. Parameters '
               'come from a YAML file: --ros-args --params-file config/owc_estimator.yaml')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(TimescaleEstimator, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(ConfigError,), args=args)


if __name__ == '__main__':
    main()
