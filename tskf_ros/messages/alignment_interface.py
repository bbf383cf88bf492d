"""The alignment node's interface: parameters, topics, QoS, outcome-to-message mapping."""

from dataclasses import fields
from pathlib import Path
from typing import Any, Optional, Union

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterType
from rclpy.qos import QoSProfile

from tskf_ros import led
from tskf_ros.led.alignment_config import AlignmentConfig
from tskf_ros.led.alignment_session import AlignmentSession, AlignOutcome
from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import ESTIMATE_TYPE, STATES_TYPE
from tskf_ros.messages.parameters import NodeConfig, parameter_values, ParamsError
from tskf_ros.messages.qos import DEFAULT_DEPTH, reliable_qos

NODE_NAME = 'alignment'
INPUT_TOPIC = 'intensity'
# the base's position command, as a ros2_control forward_command_controller takes it
COMMAND_TOPIC = 'base_position_controller/commands'
# output -> topic (relative: resolved in the node's namespace), in publishing order
OUTPUT_TOPICS = {
    'predicted': 'estimate/predicted',
    'corrected': 'estimate/corrected',
    'predicted_states': 'estimate/predicted_states',
    'corrected_states': 'estimate/corrected_states',
    'command': COMMAND_TOPIC,
}
COMMAND_TYPE = 'std_msgs/msg/Float64MultiArray'
OUTPUT_TYPES = {'predicted': ESTIMATE_TYPE, 'corrected': ESTIMATE_TYPE,
                'predicted_states': STATES_TYPE, 'corrected_states': STATES_TYPE,
                'command': COMMAND_TYPE}
# the same topics in a bag, resolved in '/'
BAG_INPUT_TOPIC = '/' + INPUT_TOPIC
BAG_OUTPUT_TOPICS = {key: '/' + topic for key, topic in OUTPUT_TOPICS.items()}
OPEN_LOOP_NOTE = ('open loop: the commands on ' + BAG_OUTPUT_TOPICS['command'] + ' do not '
                  'move the recorded receiver; the estimates are the filter on the recorded '
                  'intensities')

D, DA = ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_DOUBLE_ARRAY
B = ParameterType.PARAMETER_BOOL
# AlignmentConfig field -> (type, description, (lo, hi) or None, read_only)
SESSION_PARAMETERS = {
    'algorithm': (ParameterType.PARAMETER_STRING, 'ekf (the scanning EKF of Section IV), '
                  'hill_climbing or three_point (the baselines of Section V)', None, False),
    'controller': (ParameterType.PARAMETER_STRING, 'the controller of the ekf: p (Solanki '
                   'et al. eq. (21), u = -G x2hat) or lqg (the time-scale LQR of Bohner & '
                   'Wintz 2013 on a drift-estimating EKF; its estimates are not published)',
                   None, False),
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
    'gate': (D, 'EKF innovation gate: an intensity further than this many standard '
             'deviations from the prediction is treated as missing; 0: off', (0.0, 1e6),
             False),
    'intensity_range': (DA, 'V: [lo, hi] of a physical reading, others are treated as '
                        'missing; empty: any finite value', None, False),
    'state_limit': (D, '|x_i| or sqrt(trace P) of the EKF beyond this restarts the aligner '
                    '(diagnostics ERROR)', (1e-6, 1e300), False),
    'max_step': (D, 'deg: a command turns the base at most this much; 0: no limit',
                 (0.0, 1e6), False),
    'base_limits': (DA, 'deg: [lo, hi] joint limits of the base; commands are clamped',
                    None, False),
    'expected_rate': (D, 'Hz: the intensity rate the input frequency diagnostics expect '
                      '(FrequencyStatus); 0: 1 / dt', (0.0, 1e6), False),
    'rate_tolerance': (D, 'the input frequency is WARN outside expected_rate * (1 -/+ '
                       'rate_tolerance) (FrequencyStatus tolerance)', (0.0, 1.0), False),
}
PARAMETERS = tuple(SESSION_PARAMETERS) + ('frame_id', 'diagnostic_updater.period',
                                          'queue_depth', 'status_period')

__all__ = ['BAG_INPUT_TOPIC', 'BAG_OUTPUT_TOPICS', 'bag_outcome_messages', 'COMMAND_TOPIC',
           'COMMAND_TYPE', 'default_parameters', 'diagnostics_message', 'ESTIMATE_TYPE',
           'INPUT_TOPIC', 'load_config', 'NODE_NAME', 'NodeConfig', 'OPEN_LOOP_NOTE',
           'outcome_messages', 'OUTPUT_TOPICS', 'OUTPUT_TYPES', 'output_qos', 'PARAMETERS',
           'parameters_to_config', 'ParamsError', 'SESSION_PARAMETERS']


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
                      values['diagnostic_updater.period'], values['queue_depth'],
                      values['status_period'])


def default_parameters() -> dict:
    """Return the declared default of every parameter (Table I of Solanki et al.)."""
    defaults = AlignmentConfig()
    values = {}
    for name, (type_, _, _, _) in SESSION_PARAMETERS.items():
        value = getattr(defaults, name)
        values[name] = [float(v) for v in value] if type_ == DA else value
    values.update({'frame_id': 'receiver', 'diagnostic_updater.period': 1.0,
                   'queue_depth': 100, 'status_period': 10.0})
    return values


def load_config(params_file: Optional[Union[str, Path]] = None,
                overrides: Optional[dict] = None) -> NodeConfig:
    """
    Build the node's config from a ROS parameter YAML file, as `--params-file` would.

    The file's `alignment`, `/alignment`, `/**/alignment` or `/**` ros__parameters override
    the defaults.  Raises ParamsError naming the file and the problem.
    """
    values = parameter_values(params_file, NODE_NAME, default_parameters(), overrides)
    try:
        return parameters_to_config(values)
    except (led.AlignmentError, ValueError, TypeError, KeyError) as exc:
        raise ParamsError(f'{params_file or "defaults"}: {exc}') from None


def output_qos(config: NodeConfig, output: str) -> QoSProfile:
    """
    Return the QoS of an output's publisher: reliable, keep last.

    The command keeps the system default depth 10 (what forward_command_controller
    subscribes with); the estimates keep queue_depth.
    """
    return reliable_qos(DEFAULT_DEPTH if output == 'command' else config.queue_depth)


def outcome_messages(out: AlignOutcome, config: NodeConfig) -> list:
    """Return the (output, message) pairs to publish for an outcome, in order."""
    if out.command is None:
        return []
    msgs = []
    if out.prior is not None:
        for kind, (x, P) in (('predicted', out.prior), ('corrected', out.posterior)):
            msgs.append((kind, conversions.alignment_estimate_to_msg(
                out.stamp_ns, x, P, frame_id=config.frame_id)))
            msgs.append((kind + '_states', conversions.alignment_estimate_to_joint_state(
                out.stamp_ns, x, P, frame_id=config.frame_id)))
    msgs.append(('command', conversions.base_command_to_msg(out.command)))
    return msgs


def bag_outcome_messages(out: AlignOutcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (bag topic, message) pairs the live node publishes for an outcome."""
    return [(BAG_OUTPUT_TOPICS[key], msg) for key, msg in outcome_messages(out, config)]


def diagnostics_message(session: AlignmentSession, config: NodeConfig, stamp_ns: int, *,
                        node_name: str = NODE_NAME) -> DiagnosticArray:
    """Return the /diagnostics message of the session's counters at stamp_ns."""
    # like the estimator's, with its receiver frame as the hardware id
    return conversions.diagnostics_to_msg(stamp_ns, node_name,
                                          session.diagnostics(now_ns=stamp_ns),
                                          hardware_id=config.frame_id or node_name)
