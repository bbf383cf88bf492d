"""What the nodes share: `--help` without ROS, the Jazzy main loop, validated parameters."""

import argparse
import sys
from typing import Callable, Optional, Sequence

from rcl_interfaces.msg import (FloatingPointRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args

from tskf_ros.owc_link import BLOCKAGES


# descriptions and ranges of the dropout parameters both link simulators share
BLOCKAGE_HELP = {
    'blockage': ('link blockages: ' + ', '.join(BLOCKAGES), None),
    'drop_probability': ('Bernoulli drop probability per sample', (0.0, 1.0)),
    'ge_p_gb': ('Gilbert-Elliott P(good -> bad) per sample', (0.0, 1.0)),
    'ge_p_bg': ('Gilbert-Elliott P(bad -> good) per sample', (0.0, 1.0)),
    'ge_loss_good': ('Gilbert-Elliott loss probability in the good state', (0.0, 1.0)),
    'ge_loss_bad': ('Gilbert-Elliott loss probability in the bad state', (0.0, 1.0)),
}


def descriptor(text: str, rng: Optional[tuple] = None,
               type_: int = ParameterType.PARAMETER_DOUBLE, *,
               read_only: bool = True) -> ParameterDescriptor:
    """Describe a parameter: its text, type, optional float range (lo, hi) and read-only flag."""
    d = ParameterDescriptor(description=text, type=type_, read_only=read_only)
    if rng is not None:
        d.floating_point_range = [FloatingPointRange(from_value=rng[0], to_value=rng[1])]
    return d


def sensor_input_qos(depth: int) -> QoSProfile:
    """
    Return the QoS for a sensor input: best effort, keep last depth.

    A best-effort subscription matches reliable and best-effort publishers alike, so the
    node takes a real driver's sensor-data stream as well as a reliable bag player.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT)


def float_range(lo: float, hi: float) -> dict:
    """Return ParameterDescriptor keyword arguments for a closed floating-point range."""
    return {'floating_point_range': [FloatingPointRange(from_value=lo, to_value=hi)]}


def parse_args(prog: str, description: str,
               argv: Optional[list] = None) -> argparse.Namespace:
    """Parse the non-ROS arguments (`--help` prints usage and exits without starting ROS)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    args = remove_ros_args(sys.argv if argv is None else argv)[1:]
    return parser.parse_known_args(args)[0]


def run_node(factory: Callable[[], Node], *, name: str, description: str,
             startup_errors: tuple = (), args: Optional[list] = None) -> None:
    """
    Run one node until Ctrl-C or shutdown, in the Jazzy form of ros2/demos.

    An exception of `startup_errors` (bad parameters) ends the process with its message
    on stderr and exit code 1, not a traceback.
    """
    parse_args(name, description, args)
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except startup_errors as exc:
        print(f'{name}: cannot start: {exc}', file=sys.stderr)
        sys.exit(1)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


class ReconfigurableNode(Node):
    """
    A node whose parameters make one config object, validated whole and then applied.

    A subclass declares its parameters, names them in PARAMETERS, builds its config with
    `make_config(values)` (raising one of CONFIG_ERRORS with the reason) and hands a new
    config to its session in `reconfigure(config)`, which returns what happened.  A change
    that does not make a working config is refused with the reason, and the node keeps
    running on the old values.  `config.diagnostics_period` retimes `self.diag_timer`.
    """

    PARAMETERS: tuple = ()
    CONFIG_ERRORS: tuple = (KeyError, TypeError, ValueError)

    def start_watching_parameters(self) -> object:
        """Build the config from the declared parameters and validate every later change."""
        self._pending = None
        config = self.make_config(self.parameter_values())
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        return config

    def parameter_values(self, changes: Sequence[Parameter] = ()) -> dict:
        """Return every parameter's value, with the proposed changes on top."""
        values = {name: self.get_parameter(name).value for name in self.PARAMETERS}
        values.update({p.name: p.value for p in changes})
        return values

    def make_config(self, values: dict) -> object:
        """Build the node's config from parameter values (subclasses)."""
        raise NotImplementedError

    def reconfigure(self, config: object) -> str:
        """Hand a validated config to the session; return what it did (subclasses)."""
        raise NotImplementedError

    def _validate(self, changes: list) -> SetParametersResult:
        try:
            config = self.make_config(self.parameter_values(changes))
        except self.CONFIG_ERRORS as exc:
            self.get_logger().warning(f'parameter change refused: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        self._pending = config
        return SetParametersResult(successful=True)

    def _apply(self, changes: list) -> None:
        if self._pending is None:
            return
        config, self._pending = self._pending, None
        if config.diagnostics_period != self.config.diagnostics_period:
            self.diag_timer.timer_period_ns = int(config.diagnostics_period * 1e9)
            self.diag_timer.reset()
        self.config = config
        message = self.reconfigure(config)
        self.get_logger().info(f'parameters changed ({", ".join(p.name for p in changes)}): '
                               f'{message}')
