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

"""The timescale_estimator's interface: parameters, topics, QoS, outcome-to-message mapping."""

from dataclasses import dataclass
from operator import attrgetter
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Union

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped
import numpy as np
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import FluidPressure, Illuminance, Range, RelativeHumidity, Temperature
from std_msgs.msg import Float32, Float64, Float64MultiArray

from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import STATE_ESTIMATE_TYPE
from tskf_ros.messages.estimate_cdr import EstimateEncoder
from tskf_ros.messages.fixed_cdr import layout_decoder, rclpy_layout
from tskf_ros.messages.parameter_schema import load_schema, ParameterError
from tskf_ros.messages.parameters import NodeConfig, parameter_values, ParamsError
from tskf_ros.messages.qos import DEFAULT_DEPTH, DIAGNOSTICS_TOPIC, reliable_qos
from tskf_ros.owc.session import (ConfigError, EstimatorConfig, EstimatorSession,
                                  model_from_flat, Outcome)

NODE_NAME = 'timescale_estimator'
# the model's matrices, row-major flat lists (their shapes are inferred)
MATRICES = ('A', 'B', 'C', 'D', 'G', 'Q', 'R', 'x0', 'P0')
# topics, relative: resolved in the node's namespace
MEASUREMENT_TOPIC = 'measurement'   # the estimator's y: neutral, remapped per application
POWER_TOPIC = 'received_power'      # the OWC power meter's (the simulator's, the bags')
INPUT_TOPIC = 'input'
# output -> topic: the filter's estimates as they come, a late sample's re-run, and the
# fixed-lag smoothed estimate (only with smoothing_lag > 0).  With /diagnostics these are
# the node's five outputs; doc/interfaces.md has their layout.
OUTPUT_TOPICS = {
    'predicted': 'estimate/predicted',
    'corrected': 'estimate/corrected',
    'revised': 'estimate/revised',
    'smoothed': 'estimate/smoothed',
}

# the same topics in a bag, resolved in '/', with their types
BAG_POWER_TOPIC = '/' + POWER_TOPIC
BAG_INPUT_TOPIC = '/' + INPUT_TOPIC
BAG_OUTPUT_TOPICS = {key: '/' + topic for key, topic in OUTPUT_TOPICS.items()}
BAG_TRUTH_TOPIC = '/true_angle'
# every output is an estimate: std_msgs/msg/Float64MultiArray in the layout of
# conversions.state_estimate_to_msg (stamp, mu, kind, x, P, state names)
ESTIMATE_TYPE = STATE_ESTIMATE_TYPE


def output_key(kind: str, revised: bool = False) -> str:
    """Return the output (a key of OUTPUT_TOPICS) of an estimate of `kind`."""
    return 'revised' if revised else kind


def output_type(key: str) -> str:
    """Return the message type of an output (every one is an estimate)."""
    return ESTIMATE_TYPE


INPUT_TYPE = 'geometry_msgs/msg/AccelStamped'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

__all__ = ['BAG_INPUT_TOPIC', 'BAG_OUTPUT_TOPICS', 'BAG_POWER_TOPIC', 'BAG_TRUTH_TOPIC',
           'bag_outcome_messages', 'ConfigError', 'DEFAULT_MEASUREMENT_TYPE',
           'default_parameters', 'DIAGNOSTICS_TOPIC',
           'DIAGNOSTICS_TYPE', 'diagnostics_message', 'ESTIMATE_TYPE', 'extractor',
           'INPUT_TOPIC', 'INPUT_TYPE', 'INPUT_TYPES', 'input_from_msg', 'InputType',
           'output_type',
           'load_config', 'MATRICES', 'measurement_class', 'MEASUREMENT_TOPIC',
           'NODE_NAME', 'NodeConfig',
           'outcome_messages', 'OutcomeMessages', 'output_key', 'OUTPUT_TOPICS', 'output_qos',
           'parameters_to_config', 'ParamsError', 'POWER_TOPIC', 'estimate_mu', 'step_mus']


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
        expected_rate=values['expected_rate'], rate_tolerance=values['rate_tolerance'])
    return NodeConfig(estimator, values['frame_id'], values['diagnostic_updater.period'],
                      values['queue_depth'], values['status_period'])


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
    """
    Return the default QoS of the estimate publishers: reliable, keep last 10.

    The node lets `qos_overrides.<topic>.publisher.*` parameters change it (depth,
    durability, history, reliability: messages/qos.py's overridable()), as
    robot_localization does.
    """
    return reliable_qos(DEFAULT_DEPTH)


def step_mus(out: Outcome) -> tuple[dict[int, float], dict[int, float]]:
    """Return mu (s) of the outcome's steps by their start point and by their end point."""
    start: dict[int, float] = {}
    end: dict[int, float] = {}
    for j in out.jumps:
        start[j.stamp_ns] = end[j.sigma_ns] = j.mu
    return start, end


def estimate_mu(kind: str, stamp_ns: int, mus: tuple[dict[int, float], dict[int, float]]
                ) -> float:
    """
    Return the mu of the step an estimate comes from (0 for the prior at a first point).

    A corrected estimate at t_k comes from the step t_k -> sigma(t_k), a predicted one at
    t_k from the step into t_k.
    """
    start, end = mus
    return (end if kind == 'predicted' else start).get(stamp_ns, 0.0)


def outcome_messages(out: Outcome, config: NodeConfig) -> list:
    """Return the (output, message) pairs to publish for an Outcome, in order."""
    names = config.session.model.state_names
    mus = step_mus(out)
    return [(output_key(e.kind, e.revised), conversions.state_estimate_to_msg(
        e.kind, e.stamp_ns, estimate_mu(e.kind, e.stamp_ns, mus), e.x, e.P, names))
        for e in out.estimates]


class OutcomeMessages:
    """
    The live node's output messages: one preallocated message per output and kind.

    `messages(out)` yields what outcome_messages(out, config) returns, equal field for
    field (test_outcome_messages), but each message is reused: it is valid until the next
    one is yielded (a late sample's revisions fill the same message one after the other),
    which suits a publisher (rclpy serializes in publish) and nothing that keeps them.
    `serialized(out)` returns the same messages serialized without filling them (what the
    node publishes: canonical CDR, estimate_cdr.EstimateEncoder), the bytes rosbags
    serializes from each message.
    """

    def __init__(self, config: NodeConfig) -> None:
        names = config.session.model.state_names
        self.msgs = {(key, kind): Float64MultiArray(
            layout=conversions.state_estimate_layout(kind, names))
            for key in OUTPUT_TOPICS for kind in ('predicted', 'corrected', 'smoothed')}
        self.encoder = EstimateEncoder(names)

    def messages(self, out: Outcome,
                 wanted: Optional[Callable[[str], bool]] = None) -> Iterator[tuple]:
        """
        Yield the (output, message) pairs to publish for an Outcome, in order.

        With `wanted`, only the outputs for which wanted(output) is true are filled and
        yielded (the node skips the topics nobody subscribes to).
        """
        msgs, mus = self.msgs, None
        for e in out.estimates:
            key = output_key(e.kind, e.revised)
            if wanted is None or wanted(key):
                mus = mus or step_mus(out)
                yield key, conversions.fill_state_estimate(
                    msgs[key, e.kind], e.stamp_ns, estimate_mu(e.kind, e.stamp_ns, mus),
                    e.x, e.P)

    def serialized(self, out: Outcome,
                   wanted: Optional[Callable[[str], bool]] = None) -> list[tuple[str, bytes]]:
        """Return the (output, serialized message) pairs of messages(out, wanted), in order."""
        encode, mus, pairs = self.encoder.estimate, None, []
        for e in out.estimates:
            kind = e.kind
            key = output_key(kind, e.revised)
            if wanted is None or wanted(key):
                mus = mus or step_mus(out)
                pairs.append((key, encode(kind, e.stamp_ns,
                                          estimate_mu(kind, e.stamp_ns, mus), e.x, e.P)))
        return pairs

    def smoothed(self, stamp_ns: int, mu: float, x: np.ndarray,
                 P: np.ndarray) -> Float64MultiArray:
        """Return the smoothed output's message filled with one fixed-lag estimate."""
        return conversions.fill_state_estimate(self.msgs['smoothed', 'smoothed'], stamp_ns,
                                               mu, x, P)

    def smoothed_serialized(self, stamp_ns: int, mu: float, x: np.ndarray,
                            P: np.ndarray) -> bytes:
        """Return smoothed(stamp_ns, mu, x, P) serialized."""
        return self.encoder.estimate('smoothed', stamp_ns, mu, x, P)


def bag_outcome_messages(out: Outcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (bag topic, message) pairs the live node publishes for an Outcome."""
    return [(BAG_OUTPUT_TOPICS[key], msg) for key, msg in outcome_messages(out, config)]


def diagnostics_message(session: EstimatorSession, config: NodeConfig, stamp_ns: int, *,
                        node_name: str = NODE_NAME) -> DiagnosticArray:
    """Return the /diagnostics message of the session's counters at stamp_ns."""
    return conversions.diagnostics_to_msg(stamp_ns, node_name,
                                          session.diagnostics(now_ns=stamp_ns),
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
    # the fields in one call (the live node's every input): stamp sec, nanosec, value[,
    # variance]
    to_ns = conversions.sec_nanosec_to_ns
    fields = attrgetter('header.stamp.sec', 'header.stamp.nanosec', value,
                        *((variance,) if variance else ()))
    if variance is None:
        def stamped(msg: Any, log_ns: int) -> tuple[int, float, float]:
            sec, nanosec, y = fields(msg)
            return to_ns(sec, nanosec), float(y), 0.0
        return stamped

    def with_variance(msg: Any, log_ns: int) -> tuple[int, float, float]:
        sec, nanosec, y, var = fields(msg)
        return to_ns(sec, nanosec), float(y), float(var)
    return with_variance


# (stamp ns, value, variance) of a measurement
Sample = tuple[int, float, float]


def sample_fields(msgtype: str) -> list[str]:
    """Return the fields of a type of INPUT_TYPES that a sample reads: value[, variance]."""
    kind = INPUT_TYPES[msgtype]
    return [kind.value] + ([kind.variance] if kind.variance else [])


def sample_reader(msgtype: str, decode: Callable[[Any], Optional[tuple]],
                  slow: Callable[[Any, int], Sample]) -> Callable[[Any, int], Sample]:
    """
    Return read(cdr bytes, log ns) -> (stamp ns, value, variance) for a type of INPUT_TYPES.

    decode(bytes) -> (stamp ns or None, *the values of sample_fields(msgtype)) reads the
    fixed layout (tskf_ros.messages.fixed_cdr), None where it leaves the bytes to
    slow(bytes, log ns): a deserializer and extractor(msgtype), whose values it gives.
    """
    kind = INPUT_TYPES[msgtype]
    if not kind.stamped:
        def read_plain(data: Any, log_ns: int) -> Sample:
            got = decode(data)
            return slow(data, log_ns) if got is None else (int(log_ns), got[1], 0.0)
        return read_plain
    if kind.variance is None:
        def read_no_variance(data: Any, log_ns: int) -> Sample:
            got = decode(data)
            return slow(data, log_ns) if got is None else (got[0], got[1], 0.0)
        return read_no_variance

    def read(data: Any, log_ns: int) -> Sample:
        return decode(data) or slow(data, log_ns)
    return read


def raw_reader(msgtype: str) -> Callable[[bytes, int], Sample]:
    """
    Return read(cdr bytes, log ns): extractor(msgtype) of rclpy's deserialize_message.

    The live node's measurement subscription takes the serialized message (raw=True):
    the fixed layout read from rclpy's message class (fixed_cdr.rclpy_layout), without
    building the message; bytes it does not take (big endian, XCDR2) go through
    deserialize_message.
    """
    cls, extract = INPUT_CLASSES[msgtype], extractor(msgtype)

    def slow(data: bytes, log_ns: int) -> Sample:
        return extract(deserialize_message(data, cls), log_ns)
    return sample_reader(msgtype, layout_decoder(*rclpy_layout(cls), sample_fields(msgtype)),
                         slow)
