"""
The timescale_estimator node's inputs and outputs, without the node: a thin adapter.

The live node (tskf_ros.nodes.timescale_estimator) turns a received-power message into
`EstimatorSession.add(...)` and the resulting Outcome into messages on its topics.  The
offline replay does the same without DDS, so this module mirrors the node's private
`_publish` (topic per estimate kind, conversions for the messages) and its parameter
defaults; test_bag_replay checks both against a live node.  If the node grows a public
`outcome_messages()` this module should call it instead.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Union

import numpy as np
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from tskf_ros.estimation import Outcome
from tskf_ros.models import owc
from tskf_ros.nodes import conversions
from tskf_ros.nodes.timescale_estimator import (MATRICES, NODE_NAME, NodeConfig,
                                                parameters_to_config, SCALARS)
import yaml

__all__ = ['ESTIMATE_TYPE', 'INPUT_TYPES', 'InputType', 'JUMP_TYPE', 'OUTPUT_TOPICS',
           'ParamsError', 'default_parameters', 'load_config', 'outcome_messages',
           'output_qos']

ESTIMATE_TYPE = 'geometry_msgs/msg/TwistWithCovarianceStamped'
JUMP_TYPE = 'sensor_msgs/msg/TimeReference'
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
# (kind, revised) -> topic, as TimescaleEstimator.pubs (relative names resolved in '/')
OUTPUT_TOPICS = {
    ('predicted', False): '/estimate/predicted',
    ('corrected', False): '/estimate/corrected',
    ('mu', False): '/estimate/mu',
    ('predicted', True): '/estimate/revised/predicted',
    ('corrected', True): '/estimate/revised/corrected',
    ('mu', True): '/estimate/revised/mu',
}
DIAGNOSTICS_TOPIC = '/diagnostics'
POWER_TOPIC = '/received_power'
TRUTH_TOPIC = '/true_angle'


class ParamsError(ValueError):
    """A parameter file that cannot configure the estimator."""


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


def default_parameters() -> dict:
    """Return the node's declared parameter defaults (see TimescaleEstimator._declare)."""
    d = owc()
    matrices = {'A': d.A, 'B': (), 'C': d.C, 'D': d.D, 'G': d.G, 'Q': d.Q, 'R': d.R,
                'x0': d.x0, 'P0': d.P0}
    values: dict = {key: [float(v) for v in np.ravel(matrices[key])] for key in MATRICES}
    values.update({name: spec[0] for name, spec in SCALARS.items()})
    values.update({'model_name': d.name, 'state_names': list(d.state_names),
                   'transition': 'euler', 'history_size': 1000, 'queue_depth': 100,
                   'nonpositive_is_gap': True, 'frame_id': ''})
    return values


def load_config(params_file: Optional[Union[str, Path]] = None,
                overrides: Optional[dict] = None) -> NodeConfig:
    """
    Build the node's config from a ROS parameter YAML file, as `--params-file` would.

    The file's `timescale_estimator` (or `/**`) ros__parameters override the defaults.
    Raises ParamsError naming the file and the problem.
    """
    values = default_parameters()
    where = str(params_file) if params_file else 'defaults'
    if params_file:
        try:
            doc = yaml.safe_load(Path(params_file).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ParamsError(f'{params_file}: cannot read parameters ({exc})') from None
        section = None
        for key in (NODE_NAME, '/' + NODE_NAME, '/**'):
            if isinstance(doc.get(key), dict) and 'ros__parameters' in doc[key]:
                section = doc[key]['ros__parameters']
                break
        if section is None:
            raise ParamsError(f'{params_file}: no {NODE_NAME}: ros__parameters section')
        unknown = sorted(set(section) - set(values) - {'use_sim_time', 'diagnostics_period'})
        if unknown:
            raise ParamsError(f'{params_file}: unknown parameter(s) {", ".join(unknown)}')
        values.update(section)
    values.update(overrides or {})
    try:
        return parameters_to_config(values)
    except (ValueError, TypeError, KeyError) as exc:
        raise ParamsError(f'{where}: {exc}') from None


def output_qos(config: NodeConfig) -> QoSProfile:
    """Return the QoS of the node's estimate publishers (reliable, keep last queue_depth)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=config.queue_depth,
                      reliability=ReliabilityPolicy.RELIABLE)


def outcome_messages(out: Outcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (topic, message) pairs the live node publishes for an Outcome, in order."""
    frame = config.frame_id or config.estimator.model.name
    msgs = [(OUTPUT_TOPICS[e.kind, e.revised],
             conversions.estimate_to_msg(e.stamp_ns, e.x, e.P, frame_id=frame))
            for e in out.estimates]
    msgs += [(OUTPUT_TOPICS['mu', j.revised], conversions.jump_to_msg(j.stamp_ns, j.sigma_ns))
             for j in out.jumps]
    return msgs
