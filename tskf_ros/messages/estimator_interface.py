"""The timescale_estimator's interface: parameters, topics, QoS, outcome-to-message mapping."""

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Union

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, TwistWithCovarianceStamped
import numpy as np
from rclpy.qos import QoSProfile
from sensor_msgs.msg import (FluidPressure, Illuminance, JointState, Range, RelativeHumidity,
                             Temperature, TimeReference)
from std_msgs.msg import Float32, Float64

from tskf_ros.core.linear_models import owc
from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import ESTIMATE_TYPE, STATES_TYPE
from tskf_ros.messages.parameters import NodeConfig, parameter_values, ParamsError
from tskf_ros.messages.qos import DIAGNOSTICS_TOPIC, reliable_qos
from tskf_ros.owc.session import (ConfigError, EstimatorConfig, EstimatorSession,
                                  model_from_flat, Outcome)
from tskf_ros.owc.session.config import check_ranges

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
    'gate': (10.0, 'innovation gate: a measurement further than this many standard '
             'deviations (Mahalanobis distance) from the prediction is rejected; 0: off',
             (0.0, 1e6)),
    'state_limit': (1e9, '|x_i| or sqrt(trace P) beyond this re-initialises the filter '
                    '(diagnostics ERROR)', (1e-6, 1e300)),
    'stale_timeout': (10.0, 's without any input (node clock): diagnostics ERROR; 0: off',
                      (0.0, 1e6)),
    'min_rate_fraction': (0.5, 'input rate below this fraction of 1 / period over '
                          'rate_window: diagnostics WARN; 0: off', (0.0, 1.0)),
    'rate_window': (10.0, 's over which the input rate is measured', (0.01, 3600.0)),
}
MEASUREMENT_RANGE_HELP = ('[lo, hi]: a physical reading outside is rejected (out_of_range); '
                          'empty: any finite value')
PARAMETERS = MATRICES + tuple(SCALARS) + (
    'model_name', 'state_names', 'transition', 'history_size', 'queue_depth', 'frame_id',
    'nonpositive_is_gap', 'measurement_range', 'gate_patience', 'use_message_variance',
    'measurement_type')

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
           'JUMP_TYPE', 'load_config', 'MATRICES', 'MATRIX_HELP', 'measurement_class',
           'MEASUREMENT_RANGE_HELP', 'MEASUREMENT_TOPIC',
           'NODE_NAME', 'NodeConfig',
           'outcome_messages', 'OutcomeMessages', 'OUTPUT_TOPICS', 'output_qos',
           'PARAMETERS',
           'parameters_to_config', 'ParamsError', 'POWER_TOPIC', 'SCALARS']


def parameters_to_config(values: dict) -> NodeConfig:
    """Build the config from parameter values; raise ConfigError with the reason if bad."""
    measurement_class(values.get('measurement_type', DEFAULT_MEASUREMENT_TYPE))
    check_ranges(values, {name: spec[2] for name, spec in SCALARS.items()})
    flat = {}
    for key in MATRICES + ('measurement_range',):
        v = values[key]
        if isinstance(v, (str, bytes)) or any(isinstance(e, (bool, str)) for e in v):
            raise ConfigError(f'{key} must be a list of numbers, got {v!r}')
        flat[key] = [float(e) for e in v]
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
    """Return the declared default of every parameter (the OWC model (3) of Cai et al.)."""
    d = owc()
    matrices = {'A': d.A, 'B': (), 'C': d.C, 'D': d.D, 'G': d.G, 'Q': d.Q, 'R': d.R,
                'x0': d.x0, 'P0': d.P0}
    values: dict = {key: [float(v) for v in np.ravel(matrices[key])] for key in MATRICES}
    values.update({name: spec[0] for name, spec in SCALARS.items()})
    values.update({'model_name': d.name, 'state_names': list(d.state_names),
                   'transition': 'euler', 'history_size': 1000, 'queue_depth': 1000,
                   'nonpositive_is_gap': True, 'frame_id': '', 'measurement_range': [],
                   'gate_patience': 5, 'use_message_variance': False,
                   'measurement_type': DEFAULT_MEASUREMENT_TYPE})
    return values


def load_config(params_file: Optional[Union[str, Path]] = None,
                overrides: Optional[dict] = None) -> NodeConfig:
    """
    Build the node's config from a ROS parameter YAML file, as `--params-file` would.

    The file's `timescale_estimator` (or `/**`) ros__parameters override the defaults.
    Raises ParamsError naming the file and the problem.
    """
    values = parameter_values(params_file, NODE_NAME, default_parameters(), overrides)
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
