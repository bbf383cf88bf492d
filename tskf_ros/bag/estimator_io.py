"""
The timescale_estimator node's inputs and outputs, without the node: a thin adapter.

The live node (tskf_ros.nodes.timescale_estimator) turns a received-power message into
`EstimatorSession.add(...)` and the resulting Outcome into messages on its topics.  The
offline replay does the same without DDS through the node module's own functions
(`default_parameters`, `outcome_messages`, `OUTPUT_TOPICS`, `output_qos`), with topic
names resolved in '/'; test_bag_replay checks the result against a live node.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Union


from tskf_ros.bag.params import parameter_values, ParamsError
from tskf_ros.estimation import Outcome
from tskf_ros.nodes import conversions
from tskf_ros.nodes import timescale_estimator as node
from tskf_ros.nodes.timescale_estimator import (default_parameters, input_from_msg,
                                                NODE_NAME, NodeConfig, output_qos,
                                                parameters_to_config)

__all__ = ['ESTIMATE_TYPE', 'INPUT_TYPES', 'InputType', 'JUMP_TYPE', 'OUTPUT_TOPICS',
           'ParamsError', 'U_TOPIC', 'U_TYPE', 'default_parameters', 'input_from_msg',
           'load_config', 'outcome_messages', 'output_qos']

ESTIMATE_TYPE = 'geometry_msgs/msg/TwistWithCovarianceStamped'
JUMP_TYPE = 'sensor_msgs/msg/TimeReference'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
# (kind, revised) -> topic, as the node publishes them (relative names resolved in '/')
OUTPUT_TOPICS = {key: '/' + topic for key, topic in node.OUTPUT_TOPICS.items()}
DIAGNOSTICS_TOPIC = '/diagnostics'
POWER_TOPIC = '/received_power'
# the model's input u (EstimatorSession.add_input), as the node subscribes to it
U_TOPIC = '/' + node.INPUT_TOPIC
U_TYPE = 'geometry_msgs/msg/AccelStamped'
TRUTH_TOPIC = '/true_angle'


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


def outcome_messages(out: Outcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (topic, message) pairs the live node publishes for an Outcome, in order."""
    return [(OUTPUT_TOPICS[key], msg) for key, msg in node.outcome_messages(out, config)]
