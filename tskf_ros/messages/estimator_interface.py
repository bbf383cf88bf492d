"""The timescale_estimator's interface: parameters, topics, QoS, outcome-to-message mapping."""

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Union

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistWithCovarianceStamped
from rclpy.qos import QoSProfile
from sensor_msgs.msg import (FluidPressure, Illuminance, JointState, Range, RelativeHumidity,
                             Temperature, TimeReference)
from std_msgs.msg import Float32, Float64

from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import ESTIMATE_TYPE, STATES_TYPE
from tskf_ros.messages.parameter_schema import load_schema, ParameterError
from tskf_ros.messages.parameters import NodeConfig, parameter_values, ParamsError
from tskf_ros.messages.qos import DIAGNOSTICS_TOPIC, reliable_qos
from tskf_ros.owc.session import (ConfigError, EstimatorConfig, EstimatorSession,
                                  model_from_flat, Outcome)

NODE_NAME = 'timescale_estimator'
# the model's matrices, row-major flat lists (their shapes are inferred)
MATRICES = ('A', 'B', 'C', 'D', 'G', 'Q', 'R', 'x0', 'P0')
# topics, relative: resolved in the node's namespace
MEASUREMENT_TOPIC = 'measurement'   # the estimator's y: neutral, remapped per application
POWER_TOPIC = 'received_power'      # the OWC power meter's (the simulator's, the bags')
INPUT_TOPIC = 'input'
# (estimate kind, revised) -> output topic; '<kind>_states' is the JointState mirror
OUTPUT_TOPICS = {
    ('predicted', False): 'estimate/predicted',
    ('corrected', False): 'estimate/corrected',
    ('mu', False): 'estimate/mu',
    ('predicted_states', False): 'estimate/predicted_states',
    ('corrected_states', False): 'estimate/corrected_states',
    ('predicted', True): 'estimate/revised/predicted',
    ('corrected', True): 'estimate/revised/corrected',
    ('mu', True): 'estimate/revised/mu',
    ('predicted_states', True): 'estimate/revised/predicted_states',
    ('corrected_states', True): 'estimate/revised/corrected_states',
}

# the same topics in a bag, resolved in '/', with their types
BAG_POWER_TOPIC = '/' + POWER_TOPIC
BAG_INPUT_TOPIC = '/' + INPUT_TOPIC
BAG_OUTPUT_TOPICS = {key: '/' + topic for key, topic in OUTPUT_TOPICS.items()}
BAG_TRUTH_TOPIC = '/true_angle'
JUMP_TYPE = 'sensor_msgs/msg/TimeReference'


def output_type(key: tuple) -> str:
    """Return the message type of the output (kind, revised)."""
    kind = key[0]
    return JUMP_TYPE if kind == 'mu' else STATES_TYPE if kind.endswith('_states') \
        else ESTIMATE_TYPE


INPUT_TYPE = 'geometry_msgs/msg/AccelStamped'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

__all__ = ['BAG_INPUT_TOPIC', 'BAG_OUTPUT_TOPICS', 'BAG_POWER_TOPIC', 'BAG_TRUTH_TOPIC',
           'bag_outcome_messages', 'ConfigError', 'DEFAULT_MEASUREMENT_TYPE',
           'default_parameters', 'DIAGNOSTICS_TOPIC',
           'DIAGNOSTICS_TYPE', 'diagnostics_message', 'ESTIMATE_TYPE', 'extractor',
           'INPUT_TOPIC', 'INPUT_TYPE', 'INPUT_TYPES', 'input_from_msg', 'InputType',
           'output_type',
           'JUMP_TYPE', 'load_config', 'MATRICES', 'measurement_class', 'MEASUREMENT_TOPIC',
           'NODE_NAME', 'NodeConfig',
           'outcome_messages', 'OutcomeMessages', 'OUTPUT_TOPICS', 'output_qos',
           'parameters_to_config', 'ParamsError', 'POWER_TOPIC']


def parameters_to_config(values: dict) -> NodeConfig:
    """Build the config from parameter values; raise ConfigError with the reason if bad."""
    try:
        values = load_schema(NODE_NAME).check(values)
    except ParameterError as exc:
        raise ConfigError(str(exc)) from None
    measurement_class(values['measurement_type'])
    flat = {key: values[key] for key in MATRICES + ('measurement_range',)}
    measurement_range = tuple(flat.pop('measurement_range'))
    model = model_from_flat(name=values['model_name'],
                            state_names=tuple(values['state_names']), **flat)
    estimator = EstimatorConfig(
        model, transition=values['transition'], period=values['period'],
        dense_fraction=values['dense_fraction'], jump_factor=values['jump_factor'],
        max_gap=values['max_gap'], history_window=values['history_window'],
        history_size=values['history_size'], max_jump=values['max_jump'],
        max_backward=values['max_backward'], max_future=values['max_future'],
        nonpositive_is_gap=values['nonpositive_is_gap'], gate=values['gate'],
        gate_patience=values['gate_patience'],
        use_message_variance=values['use_message_variance'],
        measurement_range=measurement_range, state_limit=values['state_limit'],
        stale_timeout=values['stale_timeout'],
        min_rate_fraction=values['min_rate_fraction'], rate_window=values['rate_window'])
    return NodeConfig(estimator, values['frame_id'], values['diagnostics_period'],
                      values['queue_depth'])


def default_parameters() -> dict:
    """Return the default of every parameter (config/schema: the OWC model (3) of Cai et al.)."""
    return load_schema(NODE_NAME).defaults()


def load_config(params_file: Optional[Union[str, Path]] = None,
                overrides: Optional[dict] = None) -> NodeConfig:
    """
    Build the node's config from a ROS parameter YAML file, as `--params-file` would.

    The file's `timescale_estimator` (or `/**`) ros__parameters override the defaults, and
    every value is checked against the node's schema (types, ranges) as the node checks it.
    Raises ParamsError naming the file and the problem.
    """
    values = parameter_values(params_file, load_schema(NODE_NAME), overrides)
    try:
        return parameters_to_config(values)
    except (ValueError, TypeError, KeyError) as exc:
        raise ParamsError(f'{params_file or "defaults"}: {exc}') from None


def output_qos(config: NodeConfig) -> QoSProfile:
    """Return the QoS of the estimate publishers: reliable, keep last queue_depth."""
    return reliable_qos(config.queue_depth)


def outcome_messages(out: Outcome, config: NodeConfig) -> list:
    """Return the ((kind, revised), message) pairs to publish for an Outcome, in order."""
    frame, names = config.frame_id, config.session.model.state_names
    msgs = []
    for e in out.estimates:
        msgs.append(((e.kind, e.revised),
                     conversions.estimate_to_msg(e.stamp_ns, e.x, e.P, frame_id=frame)))
        msgs.append(((e.kind + '_states', e.revised), conversions.estimate_to_joint_state(
            e.stamp_ns, e.x, e.P, names, frame_id=frame)))
    msgs += [(('mu', j.revised), conversions.jump_to_msg(j.stamp_ns, j.sigma_ns))
             for j in out.jumps]
    return msgs


class OutcomeMessages:
    """
    The live node's output messages: one preallocated message per output, filled in place.

    `messages(out)` yields what outcome_messages(out, config) returns, equal field for
    field (test_outcome_messages), but each message is reused: it is valid until the next
    one is yielded (a late sample's revisions fill the same message one after the other),
    which suits a publisher (rclpy serializes in publish) and nothing that keeps them.
    Filling costs a few microseconds where building nine nested message objects per
    estimate costs tens.
    """

    def __init__(self, config: NodeConfig) -> None:
        frame, names = config.frame_id, list(config.session.model.state_names)
        self.msgs = {}
        for key in OUTPUT_TOPICS:
            kind = output_type(key)
            if kind == ESTIMATE_TYPE:
                msg = TwistWithCovarianceStamped()
                msg.header.frame_id = frame
            elif kind == STATES_TYPE:
                msg = JointState(name=names, position=[0.0] * len(names),
                                 velocity=[0.0] * len(names))
                msg.header.frame_id = frame
            else:
                msg = TimeReference(source='sigma')
            self.msgs[key] = msg

    def messages(self, out: Outcome,
                 wanted: Optional[Callable[[tuple], bool]] = None) -> Iterator[tuple]:
        """
        Yield the ((kind, revised), message) pairs to publish for an Outcome, in order.

        With `wanted`, only the outputs for which wanted(key) is true are filled and yielded
        (the node skips the topics nobody subscribes to).
        """
        msgs = self.msgs
        for e in out.estimates:
            key, mirror = (e.kind, e.revised), (e.kind + '_states', e.revised)
            if wanted is None or wanted(key):
                yield key, conversions.fill_estimate_msg(msgs[key], e.stamp_ns, e.x, e.P)
            if wanted is None or wanted(mirror):
                yield mirror, conversions.fill_joint_state(msgs[mirror], e.stamp_ns, e.x, e.P)
        for j in out.jumps:
            key = ('mu', j.revised)
            if wanted is None or wanted(key):
                yield key, conversions.fill_jump_msg(msgs[key], j.stamp_ns, j.sigma_ns)


def bag_outcome_messages(out: Outcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (bag topic, message) pairs the live node publishes for an Outcome."""
    return [(BAG_OUTPUT_TOPICS[key], msg) for key, msg in outcome_messages(out, config)]


def diagnostics_message(session: EstimatorSession, config: NodeConfig, stamp_ns: int, *,
                        node_name: str = NODE_NAME) -> DiagnosticArray:
    """Return the /diagnostics message of the session's counters at stamp_ns."""
    level, message, values = session.diagnostics(now_ns=stamp_ns)
    return conversions.diagnostics_to_msg(stamp_ns, f'{node_name}: time-scale filter', level,
                                          message, values,
                                          hardware_id=config.frame_id or node_name)


def input_from_msg(msg: AccelStamped, session: EstimatorSession) -> tuple:
    """Return (stamp ns, u) of an input message for the session's model (B's columns)."""
    return conversions.msg_to_input(msg, session.u.size)


@dataclass(frozen=True)
class InputType:
    """How a stamped scalar type carries a measurement: value field, variance field."""

    value: str
    variance: Optional[str]
    stamped: bool = True


# Stamped scalars of common_interfaces the offline replay takes as the measurement y.
INPUT_TYPES = {
    'sensor_msgs/msg/Illuminance': InputType('illuminance', 'variance'),
    'sensor_msgs/msg/Temperature': InputType('temperature', 'variance'),
    'sensor_msgs/msg/FluidPressure': InputType('fluid_pressure', 'variance'),
    'sensor_msgs/msg/RelativeHumidity': InputType('relative_humidity', 'variance'),
    'sensor_msgs/msg/Range': InputType('range', None),
    'std_msgs/msg/Float64': InputType('data', None, stamped=False),
    'std_msgs/msg/Float32': InputType('data', None, stamped=False),
}
DEFAULT_MEASUREMENT_TYPE = 'sensor_msgs/msg/Illuminance'
INPUT_CLASSES = {
    'sensor_msgs/msg/Illuminance': Illuminance, 'sensor_msgs/msg/Temperature': Temperature,
    'sensor_msgs/msg/FluidPressure': FluidPressure,
    'sensor_msgs/msg/RelativeHumidity': RelativeHumidity, 'sensor_msgs/msg/Range': Range,
    'std_msgs/msg/Float64': Float64, 'std_msgs/msg/Float32': Float32,
}


def measurement_class(msgtype: str) -> type:
    """Return the message class of a type of INPUT_TYPES; raise ConfigError for another."""
    if msgtype not in INPUT_TYPES:
        raise ConfigError(f'measurement_type must be one of {", ".join(INPUT_TYPES)}, got '
                          f'{msgtype!r}')
    return INPUT_CLASSES[msgtype]


def extractor(msgtype: str) -> Callable[[Any, int], tuple[int, float, float]]:
    """Return f(msg, log_time_ns) -> (stamp ns, value, variance) for a type of INPUT_TYPES."""
    kind = INPUT_TYPES[msgtype]
    value, variance = kind.value, kind.variance
    if not kind.stamped:
        return lambda msg, log_ns: (int(log_ns), float(getattr(msg, value)), 0.0)
    if variance is None:
        return lambda msg, log_ns: (conversions.stamp_to_ns(msg.header.stamp),
                                    float(getattr(msg, value)), 0.0)
    return lambda msg, log_ns: (conversions.stamp_to_ns(msg.header.stamp),
                                float(getattr(msg, value)), float(getattr(msg, variance)))
