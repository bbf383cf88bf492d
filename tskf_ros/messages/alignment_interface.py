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

"""The alignment node's interface: parameters, topics, QoS, outcome-to-message mapping."""

from dataclasses import fields
from pathlib import Path
from typing import Any, Optional, Sequence, TYPE_CHECKING, Union

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from tskf_ros import led
from tskf_ros.led.alignment_config import AlignmentConfig
from tskf_ros.led.alignment_session import AlignmentSession, AlignOutcome
from tskf_ros.led.pat_config import PatConfig
from tskf_ros.led.pointing_stats import Transition
from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import STATE_ESTIMATE_TYPE
from tskf_ros.messages.pan_tilt_messages import check_joints
from tskf_ros.messages.parameter_schema import load_schema, ParameterError
from tskf_ros.messages.parameters import NodeConfig, parameter_values, ParamsError
from tskf_ros.messages.qos import DEFAULT_DEPTH, reliable_qos

if TYPE_CHECKING:       # (the two-axis modules: imported for axes 2 only)
    from tskf_ros.led.pan_tilt_stream import PanTiltStream

NODE_NAME = 'alignment'
INPUT_TOPIC = 'intensity'
# the base's position command, as a ros2_control forward_command_controller takes it
COMMAND_TOPIC = 'base_position_controller/commands'
# output -> topic (relative: resolved in the node's namespace), in publishing order
OUTPUT_TOPICS = {
    'predicted': 'estimate/predicted',
    'corrected': 'estimate/corrected',
    'command': COMMAND_TOPIC,
}
COMMAND_TYPE = 'std_msgs/msg/Float64MultiArray'
# the supervisor's state (acquiring, tracking, lost; disabled), latched: pat_state_qos
PAT_STATE_TOPIC = 'pat_state'
PAT_STATE_TYPE = 'std_msgs/msg/String'
PAT_PREFIX = 'pat.'          # the PatConfig fields' parameter names: pat.<field>
# the EKF's estimates: the estimator node's estimate layout (conversions.state_estimate_to_msg),
# states conversions.ALIGNMENT_STATE_NAMES (x1 in V, x2 in rad)
ESTIMATE_TYPE = STATE_ESTIMATE_TYPE
OUTPUT_TYPES = {'predicted': ESTIMATE_TYPE, 'corrected': ESTIMATE_TYPE,
                'command': COMMAND_TYPE}
# the same topics in a bag, resolved in '/'
BAG_INPUT_TOPIC = '/' + INPUT_TOPIC
BAG_OUTPUT_TOPICS = {key: '/' + topic for key, topic in OUTPUT_TOPICS.items()}
BAG_PAT_STATE_TOPIC = '/' + PAT_STATE_TOPIC
OPEN_LOOP_NOTE = ('open loop: the commands on ' + BAG_OUTPUT_TOPICS['command'] + ' do not '
                  'move the recorded receiver; the estimates are the filter on the recorded '
                  'intensities')

__all__ = ['BAG_INPUT_TOPIC', 'BAG_OUTPUT_TOPICS', 'bag_outcome_messages',
           'BAG_PAT_STATE_TOPIC', 'bag_pat_state_messages', 'COMMAND_TOPIC', 'COMMAND_TYPE',
           'default_parameters', 'diagnostics_message', 'ESTIMATE_TYPE',
           'INPUT_TOPIC', 'load_config', 'NODE_NAME', 'NodeConfig', 'OPEN_LOOP_NOTE',
           'outcome_messages', 'OUTPUT_TOPICS', 'OUTPUT_TYPES', 'output_qos',
           'PAT_PREFIX', 'PAT_STATE_TOPIC', 'PAT_STATE_TYPE', 'pat_state_message',
           'pat_state_qos', 'parameters_to_config', 'ParamsError']


def parameters_to_config(values: dict) -> NodeConfig:
    """Build the config from parameter values; raise AlignmentError with the reason if bad."""
    try:
        values = load_schema(NODE_NAME).check(values)
        check_joints(values)
    except ParameterError as exc:
        raise led.AlignmentError(str(exc)) from None
    if values['axes'] == 2:     # (the two-axis modules only then)
        from tskf_ros.messages.pan_tilt_interface import pan_tilt_config
        return pan_tilt_config(values)
    session = {f.name: values[f.name] for f in fields(AlignmentConfig) if f.name != 'pat'}
    arrays = {k: tuple(v) for k, v in session.items() if isinstance(v, list)}
    pat = PatConfig(**{f.name: values[PAT_PREFIX + f.name] for f in fields(PatConfig)})
    return NodeConfig(AlignmentConfig(**{**session, **arrays}, pat=pat), values['frame_id'],
                      values['diagnostic_updater.period'], values['queue_depth'],
                      values['status_period'])


def default_parameters() -> dict:
    """Return the default of every parameter (config/schema: Table I of Solanki et al.)."""
    return load_schema(NODE_NAME).defaults()


def load_config(params_file: Optional[Union[str, Path]] = None,
                overrides: Optional[dict] = None) -> NodeConfig:
    """
    Build the node's config from a ROS parameter YAML file, as `--params-file` would.

    The file's `alignment`, `/alignment`, `/**/alignment` or `/**` ros__parameters override
    the defaults, each checked against the node's schema.  Raises ParamsError naming the
    file and the problem.  The offline tools that read it replay one axis: a file with
    `axes: 2` is refused.
    """
    values = parameter_values(params_file, load_schema(NODE_NAME), overrides)
    try:
        config = parameters_to_config(values)
    except (led.AlignmentError, ValueError, TypeError, KeyError) as exc:
        raise ParamsError(f'{params_file or "defaults"}: {exc}') from None
    if not isinstance(config.session, AlignmentConfig):
        raise ParamsError(f'{params_file or "defaults"}: axes 2: the offline tools replay one '
                          'axis; the two-axis loop runs live (pan_tilt_loop.launch.py)')
    return config


def output_qos(config: NodeConfig, output: str) -> QoSProfile:
    """
    Return the QoS of an output's publisher: reliable, keep last.

    The command keeps the system default depth 10 (what forward_command_controller
    subscribes with); the estimates keep queue_depth.
    """
    return reliable_qos(DEFAULT_DEPTH if output == 'command' else config.queue_depth)


def pat_state_qos() -> QoSProfile:
    """Return the QoS of pat_state: reliable, transient local, keep last 1 (latched)."""
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def pat_state_message(transition: Transition) -> String:
    """Return the pat_state message of a state transition: the state entered."""
    return String(data=transition.new)


def bag_pat_state_messages(transitions: Sequence[Transition]) -> list[tuple[str, String]]:
    """Return the (bag topic, message) pairs the live node publishes for transitions."""
    return [(BAG_PAT_STATE_TOPIC, pat_state_message(t)) for t in transitions]


def outcome_messages(out: AlignOutcome, config: NodeConfig) -> list:
    """Return the (output, message) pairs to publish for an outcome, in order."""
    if out.command is None:
        return []
    msgs = []
    if out.prior is not None:
        # both come from the step into t_k: mu = t_k - t_{k-1} (the update at t_k does not
        # depend on the step out of t_k, so the corrected estimate is published at once)
        for kind, (x, P) in (('predicted', out.prior), ('corrected', out.posterior)):
            msgs.append((kind, conversions.alignment_state_to_msg(kind, out.stamp_ns, out.mu,
                                                                  x, P)))
    msgs.append(('command', conversions.base_command_to_msg(out.command)))
    return msgs


def bag_outcome_messages(out: AlignOutcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (bag topic, message) pairs the live node publishes for an outcome."""
    return [(BAG_OUTPUT_TOPICS[key], msg) for key, msg in outcome_messages(out, config)]


def diagnostics_message(session: Union[AlignmentSession, 'PanTiltStream'], config: NodeConfig,
                        stamp_ns: int, *,
                        node_name: str = NODE_NAME) -> DiagnosticArray:
    """Return the /diagnostics message of the session's counters at stamp_ns."""
    # like the estimator's, with its receiver frame as the hardware id
    return conversions.diagnostics_to_msg(stamp_ns, node_name,
                                          session.diagnostics(now_ns=stamp_ns),
                                          hardware_id=config.frame_id or node_name)
