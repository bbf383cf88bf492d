"""
The alignment node's inputs and outputs, without the node: a thin adapter.

The live node (tskf_ros.nodes.alignment) turns an intensity message into
`AlignmentSession.add(stamp, volts)` and the resulting AlignOutcome into messages on its
topics.  The offline replay does the same without DDS through the node module's own
functions (`default_parameters`, `outcome_messages`, `diagnostics_message`,
`OUTPUT_TOPICS`, `output_qos`), with topic names resolved in '/'; test_bag_replay checks
the result against a live node.

Open loop: replaying recorded intensities, the commands do not move the recorded
receiver (the intensities were recorded under whatever the base did then), so the
estimates show how the filter reads the recorded data, not a closed alignment run.
"""

from pathlib import Path
from typing import Any, Optional, Union

from tskf_ros import led
from tskf_ros.alignment import AlignOutcome
from tskf_ros.bag.params import parameter_values, ParamsError
from tskf_ros.nodes import alignment as node
from tskf_ros.nodes.alignment import (default_parameters, diagnostics_message, NODE_NAME,
                                      NodeConfig, output_qos, parameters_to_config)

__all__ = ['COMMAND_TYPE', 'ESTIMATE_TYPE', 'INPUT_TOPIC', 'OPEN_LOOP_NOTE', 'OUTPUT_TOPICS',
           'OUTPUT_TYPES', 'ParamsError', 'default_parameters', 'diagnostics_message',
           'load_config', 'outcome_messages', 'output_qos']

COMMAND_TYPE = 'std_msgs/msg/Float64MultiArray'
ESTIMATE_TYPE = 'geometry_msgs/msg/TwistWithCovarianceStamped'
# output -> topic, as the node publishes them (relative names resolved in '/')
OUTPUT_TOPICS = {key: '/' + topic for key, topic in node.OUTPUT_TOPICS.items()}
OUTPUT_TYPES = {'predicted': ESTIMATE_TYPE, 'corrected': ESTIMATE_TYPE,
                'command': COMMAND_TYPE}
INPUT_TOPIC = '/' + node.INPUT_TOPIC
OPEN_LOOP_NOTE = ('open loop: the commands on ' + OUTPUT_TOPICS['command'] + ' do not move '
                  'the recorded receiver; the estimates are the filter on the recorded '
                  'intensities')
# keys of a parameter file the node takes besides its own parameters


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


def outcome_messages(out: AlignOutcome, config: NodeConfig) -> list[tuple[str, Any]]:
    """Return the (topic, message) pairs the live node publishes for an outcome, in order."""
    return [(OUTPUT_TOPICS[key], msg) for key, msg in node.outcome_messages(out, config)]
