"""The timescale_estimator node: the time-scale Kalman filter of Cai et al. on a stream."""

from typing import Any, Optional

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistWithCovarianceStamped
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor, ParameterType
from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState, TimeReference

from tskf_ros.core.timescale_kalman import FilterError, TRANSITIONS
from tskf_ros.messages.conversions import ESTIMATE_TYPE, STATES_TYPE
from tskf_ros.messages.estimator_interface import (ConfigError, default_parameters,
                                                   diagnostics_message, extractor,
                                                   input_from_msg, INPUT_TOPIC, INPUT_TYPES,
                                                   JUMP_TYPE, MATRICES, MATRIX_HELP,
                                                   measurement_class, MEASUREMENT_RANGE_HELP,
                                                   MEASUREMENT_TOPIC, NODE_NAME, NodeConfig,
                                                   OutcomeMessages, output_qos, OUTPUT_TOPICS,
                                                   output_type, PARAMETERS,
                                                   parameters_to_config, SCALARS)
from tskf_ros.messages.parameters import float_range
from tskf_ros.messages.qos import sensor_input_qos
from tskf_ros.nodes.node_base import ReconfigurableNode, run_node
from tskf_ros.owc.session import EstimatorSession, Outcome
from tskf_ros.owc.session.diagnostics import status_line


class TimescaleEstimator(ReconfigurableNode):
    """Node wrapping EstimatorSession: received power in, estimates and diagnostics out."""

    PARAMETERS = PARAMETERS
    SESSION = EstimatorSession
    CONFIG_ERRORS = (ConfigError, FilterError, KeyError, TypeError, ValueError)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None,
                 cli_args: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides, cli_args=cli_args)
        qos_in = sensor_input_qos(self.config.queue_depth)
        msgtype = self.get_parameter('measurement_type').value
        self.extract = extractor(msgtype)
        self.sub = self.create_subscription(
            measurement_class(msgtype), MEASUREMENT_TOPIC, self._on_measurement, qos_in,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost))
        self.input_sub = self.create_subscription(AccelStamped, INPUT_TOPIC, self._on_input,
                                                  qos_in)
        qos_out = output_qos(self.config)
        types = {JUMP_TYPE: TimeReference, STATES_TYPE: JointState,
                 ESTIMATE_TYPE: TwistWithCovarianceStamped}
        self.pubs = {key: self.create_publisher(types[output_type(key)], topic, qos_out)
                     for key, topic in OUTPUT_TOPICS.items()}
        self.outputs = OutcomeMessages(self.config)
        self.start_diagnostics()
        self.watch_clock_jumps()
        self.start_services()
        m = self.config.session.model
        self.model_source = (
            f'parameters ({", ".join(self.matrices_given)} given)' if self.matrices_given else
            "the built-in default, Cai et al.'s model (3): no A, C, ... given; pass "
            '--params-file config/<model>_estimator.yaml to choose a model')
        self.get_logger().info(
            f'estimating {m.name} (n = {m.A.shape[0]}, states {", ".join(m.state_names)}) '
            f'with the {self.config.session.transition} transition; the model comes from '
            f'{self.model_source}')

    # -- parameters -----------------------------------------------------------------------

    def _declare(self) -> None:
        defaults = default_parameters()
        # declared without a value, a matrix takes the one given at start (a parameter
        # file, -p, parameter_overrides) if any: that is how the node tells which were given
        for key in MATRICES:
            self.declare_parameter(key, None, ParameterDescriptor(
                description=MATRIX_HELP[key], dynamic_typing=True))
        self.matrices_given = tuple(
            key for key in MATRICES if self.get_parameter(key).type_ != Parameter.Type.NOT_SET)
        self.set_parameters([Parameter(key, value=defaults[key]) for key in MATRICES
                             if key not in self.matrices_given])
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
            description=('depth of the input and output queues (1000: 0.5 s of a 2 kHz '
                         'stream, the margin a loaded machine needs)'), read_only=True,
            type=ParameterType.PARAMETER_INTEGER,
            integer_range=[IntegerRange(from_value=1, to_value=100_000)]))
        gap_help = ('a measurement <= 0 is an invalid reading, a gap (Cai IV-C: power); '
                    'false for models whose output may be negative')
        self.declare_parameter('nonpositive_is_gap', defaults['nonpositive_is_gap'],
                               ParameterDescriptor(description=gap_help,
                                                   type=ParameterType.PARAMETER_BOOL))
        self.declare_parameter('gate_patience', defaults['gate_patience'], ParameterDescriptor(
            description='consecutive gated samples after which the next one that fails the '
            'gate re-initialises the filter (an unstable model need not widen its gate)',
            type=ParameterType.PARAMETER_INTEGER,
            integer_range=[IntegerRange(from_value=0, to_value=1_000_000)]))
        self.declare_parameter('measurement_type', defaults['measurement_type'],
                               ParameterDescriptor(
                                   description='the message type of the measurement topic: a '
                                   'stamped scalar (the value and, where the type has one, '
                                   'its variance); an unstamped std_msgs type is stamped '
                                   'with its time of arrival', read_only=True,
                                   additional_constraints='one of ' + ', '.join(INPUT_TYPES),
                                   type=ParameterType.PARAMETER_STRING))
        self.declare_parameter('use_message_variance', defaults['use_message_variance'],
                               ParameterDescriptor(
                                   description="a sample's own variance (> 0) is its "
                                   'measurement noise R_d, as robot_localization uses the '
                                   "message covariance; 0 or false: the model's R / mu",
                                   type=ParameterType.PARAMETER_BOOL))
        self.declare_parameter('measurement_range', defaults['measurement_range'],
                               ParameterDescriptor(description=MEASUREMENT_RANGE_HELP,
                                                   dynamic_typing=True))
        self.declare_parameter('frame_id', defaults['frame_id'], ParameterDescriptor(
            description='frame_id of the estimates: a TF frame, or empty',
            type=ParameterType.PARAMETER_STRING))

    def make_config(self, values: dict) -> NodeConfig:
        """Build the node's config; raises with the reason if it makes no working filter."""
        return parameters_to_config(values)

    def reconfigure(self, config: NodeConfig) -> str:
        """Switch the session to a validated config; return what it did."""
        self.outputs = OutcomeMessages(config)
        return self.session.reconfigure(config.session).message

    # -- data -----------------------------------------------------------------------------

    def _on_measurement(self, msg: Any) -> None:
        now_ns = self.get_clock().now().nanoseconds
        # an unstamped type (std_msgs Float64, Float32) is stamped with its time of arrival
        stamp_ns, value, variance = self.extract(msg, now_ns)
        out = self.session.add(stamp_ns, value, variance, now_ns=now_ns)
        self._report(out)
        self._publish(out)

    def _on_lost(self, info: QoSMessageLostInfo) -> None:
        # the middleware's count of measurements lost in transport (diagnostics: filter
        # health); a queue overflow is not reported here
        self.session.stats.messages_lost = info.total_count

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
        # each message is reused: published (serialized) before the next one is filled; an
        # output nobody subscribes to (its topic is volatile) is neither filled nor published
        for key, msg in self.outputs.messages(out, self._subscribed):
            self.pubs[key].publish(msg)

    def _subscribed(self, key: tuple) -> bool:
        return self.pubs[key].get_subscription_count() > 0

    def restart(self, why: str, reason: str = 'clock_jump') -> None:
        """Re-initialise the filter, saying why (nothing to do before a sample)."""
        if self.session.pending() is None:
            return
        out = self.session.reset(reason, why)
        self.get_logger().warning(f'filter re-initialised: {out.message}')

    def status_line(self, rate: float) -> str:
        """Return the INFO status line: rate, gaps, last estimate, resets."""
        return status_line(self.session.stats, rate, self.session.kf.x)

    def diagnostics_message(self, stamp_ns: int) -> DiagnosticArray:
        """Return the session's counters as a /diagnostics message."""
        return diagnostics_message(self.session, self.config, stamp_ns,
                                   node_name=self.get_name())


DESCRIPTION = ('Time-scale Kalman filter on received power. Parameters '
               'come from a YAML file: --ros-args --params-file config/owc_estimator.yaml')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(TimescaleEstimator, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(ConfigError,), args=args)


if __name__ == '__main__':
    main()
