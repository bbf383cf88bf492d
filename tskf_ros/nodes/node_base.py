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

"""What the nodes share: parameters from their schema, diagnostics, the simulators' clock."""

from dataclasses import fields
import gc
import math
import time
from typing import Any, Callable, Optional, Protocol, Sequence, TypeVar

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import ClockChange, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import Illuminance, JointState
from std_srvs.srv import Trigger

from tskf_ros.core.diagnostic_status import FrequencyParams, FrequencyStatus, Status
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.names import OUTPUT_FREQUENCY, RESET_SERVICE, TRUTH_TOPIC
from tskf_ros.messages.parameter_schema import load_schema, ParameterSchema
from tskf_ros.messages.qos import DEFAULT_DEPTH, DIAGNOSTICS_TOPIC, SENSOR_OUTPUT_QOS, TRUTH_QOS
from tskf_ros.nodes.clock_watch import ClockWatch
from tskf_ros.nodes.status_line import StatusLine

# a simulator takes at most this many samples per callback when catching up
MAX_BATCH = 10_000
# its output frequency is WARN outside rate * (1 -/+ this): it catches up in batches
SIMULATOR_RATE_TOLERANCE = 0.5
# the parameter of diagnostic_updater's Updater: status names '<fully qualified name>: task'
USE_FQN = 'diagnostic_updater.use_fqn'
# a link config dataclass of the core (OwcLinkConfig, LedLinkConfig)
LinkConfig = TypeVar('LinkConfig')


class NodeSettings(Protocol):
    """What ReconfigurableNode reads of a node's config: its session's part, its period."""

    @property
    def session(self) -> Any:
        """Return the config the session is built from and reconfigured with."""

    @property
    def diagnostics_period(self) -> float:
        """Return the seconds between two /diagnostics messages."""

    @property
    def status_period(self) -> float:
        """Return the seconds between two INFO status lines (0: none)."""


class SimulatorSettings(Protocol):
    """What LinkSimulatorNode reads of a simulator's config."""

    @property
    def link(self) -> Any:
        """Return the link config of the core."""

    @property
    def start_time(self) -> float:
        """Return the stamp (s) of sample 0; 0: the clock at the start."""

    @property
    def wait_for_subscribers(self) -> int:
        """Return how many subscribers the sensor topic needs before sample 0 goes."""


class ReconfigurableNode(Node):
    """
    A filtering node: one config object validated whole, diagnostics, and clock-jump resets.

    A subclass names its parameter schema in SCHEMA (config/schema/<SCHEMA>.yaml: every
    parameter is declared from it, see messages/parameter_schema.py), builds its config
    with `make_config(values)` (raising one of CONFIG_ERRORS with the reason) and hands a
    new config to its session in `reconfigure(config)`, which returns what happened.  A
    change the schema refuses, or that does not make a working config, is refused with the
    reason, and the node keeps running on the old values.  `start_diagnostics()` publishes
    `diagnostics_message(now)` on /diagnostics every `config.diagnostics_period`
    (diagnostic_updater.period) and logs `status_line(rate)` every `config.status_period`,
    both retimed when they change.  `watch_clock_jumps()` calls `restart(why)` when the
    clock jumps back or changes source (use_sim_time with a looped bag).
    """

    SCHEMA = ''
    CONFIG_ERRORS: tuple = (KeyError, TypeError, ValueError)
    # the session class of the core, built from config.session
    SESSION: Callable[[Any], Any]
    # gc.freeze() at the first /diagnostics after a sample (own_process() sets it: a
    # process of the node's own)
    freeze_heap = False

    def __init__(self, node_name: str, *, context=None, namespace: Optional[str] = None,
                 parameter_overrides: Optional[list] = None,
                 cli_args: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides, cli_args=cli_args)
        self.schema: ParameterSchema = load_schema(self.SCHEMA)
        # the parameters given at start (a file, -p, a launch file, parameter_overrides)
        self.parameters_given = self.schema.declare(self)
        self.config = self.start_watching_parameters()
        self.session = self.SESSION(self.config.session)
        # the node clock's time in ns (see watch_clock_jumps)
        self.now_ns: Callable[[], int] = self.clock_ns
        self.clock_watch = ClockWatch(self)

    def own_process(self) -> None:
        """
        Take the process as the node's own: freeze its heap now and after the first sample.

        gc.freeze() moves every object made so far (the modules of numpy, rclpy, the
        core, the node's set-up) out of the cyclic collector's reach, and again at the
        first /diagnostics after a sample (what the first sample loaded).  Without it a
        full collection walks them all: tens of ms of the executor's thread (55 ms at load
        average 5, 4 December 2026), in which the input queue fills; the node's history
        of points is what makes full collections come, every few 10 000 inputs.  Only for
        a process that runs this node alone (node_runner.run_node): the objects of other
        code in the process would be frozen too.
        """
        self.freeze_heap = True
        gc.freeze()

    def when_spinning(self, action: Callable[[], None]) -> None:
        """
        Run action once, from the executor's first turn (a one-shot 0 s timer), not now.

        For a node's start-up log lines: rclpy's first log line of a process finds its
        caller's source file through `inspect`, which walks every loaded module (about
        0.2 s with numpy and rclpy loaded); from the executor it overlaps the middleware's
        discovery of the node's topics instead of delaying them.
        """
        timer = None

        def once() -> None:
            if timer is not None:
                timer.cancel()
            action()
        timer = self.create_timer(0.0, once)

    def start_watching_parameters(self) -> NodeSettings:
        """Build the config from the declared parameters and validate every later change."""
        self._pending = None
        config = self.make_config(self.parameter_values())
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        return config

    def parameter_values(self, changes: Sequence[Parameter] = ()) -> dict:
        """Return every parameter's value, with the proposed changes on top."""
        return parameter_values(self, self.schema, changes)

    def make_config(self, values: dict) -> NodeSettings:
        """Build the node's config from parameter values (subclasses)."""
        raise NotImplementedError

    def reconfigure(self, config: NodeSettings) -> str:
        """Hand a validated config to the session; return what it did (subclasses)."""
        raise NotImplementedError

    def diagnostics_message(self, stamp_ns: int) -> DiagnosticArray:
        """Return the /diagnostics message of the session at stamp_ns (subclasses)."""
        raise NotImplementedError

    def restart(self, why: str, reason: str = 'clock_jump') -> None:
        """Restart the session (after a clock jump, by default), saying why (subclasses)."""
        raise NotImplementedError

    def status_count(self) -> int:
        """Return the samples received so far (the status line's rate counts them)."""
        return self.session.stats.received

    def status_line(self, rate: float) -> str:
        """Return the INFO status line, rate = status_count() per second (subclasses)."""
        raise NotImplementedError

    def start_services(self) -> None:
        """Offer ~/reset (std_srvs/srv/Trigger): restart the session from its initial state."""
        self.reset_service = self.create_service(Trigger, RESET_SERVICE, self._on_reset)

    def _on_reset(self, request: Trigger.Request,
                  response: Trigger.Response) -> Trigger.Response:
        self.restart('reset by the ~/reset service', 'service')
        response.success, response.message = True, 'session restarted from its initial state'
        return response

    def start_diagnostics(self) -> None:
        """Publish diagnostics every diagnostics_period s, log a status every status_period."""
        self.diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                              DEFAULT_DEPTH)
        self.diag_timer = self.create_timer(self.config.diagnostics_period,
                                            self.publish_diagnostics)
        self.status = StatusLine(self, self.config.status_period, self.status_count,
                                 self.status_line)

    def publish_diagnostics(self) -> DiagnosticArray:
        """Publish (and return) the session's counters on /diagnostics."""
        if self.freeze_heap and self.status_count():
            # what the first sample loaded (numba's and LLVM's objects where it compiled
            # the kernels, modules imported on demand) joins the start's (own_process)
            # out of the collector's reach
            gc.freeze()
            self.freeze_heap = False
        msg = self.diagnostics_message(self.get_clock().now().nanoseconds)
        self.diag_pub.publish(msg)
        return msg

    def clock_ns(self) -> int:
        """Return the node clock's time in ns (self.now_ns() may read it more cheaply)."""
        return self.get_clock().now().nanoseconds

    def watch_clock_jumps(self) -> None:
        """
        Restart the session when the clock jumps back by 1 ms or more or changes source.

        From here on self.now_ns() (before: clock_ns()) follows the clock's source without
        asking rclpy for it on each call: while ROS time is inactive the node clock is the
        system clock (rcutils reads CLOCK_REALTIME, as time.time_ns does), read without
        building a Time; while it is active (use_sim_time with /clock), the clock's now().
        """
        clock = self.get_clock()
        self._follow_clock(getattr(clock, 'ros_time_is_active', True))
        self._jump_handle = clock.create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1_000_000),
                          on_clock_change=True),
            post_callback=self._on_clock_jump)

    def _follow_clock(self, ros_time: bool) -> None:
        self.now_ns = self.clock_ns if ros_time else time.time_ns

    def _on_clock_jump(self, jump: TimeJump) -> None:
        if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED,
                                 ClockChange.ROS_TIME_DEACTIVATED):
            self._follow_clock(jump.clock_change == ClockChange.ROS_TIME_ACTIVATED)
            why = f'clock source changed ({jump.clock_change.name})'
        else:
            why = f'clock jumped {jump.delta.nanoseconds / 1e9:.3f} s'
        self.restart(why, 'clock_jump')

    def _validate(self, changes: list) -> SetParametersResult:
        if not self._own(changes):      # rclpy's own (qos_overrides.*, use_sim_time)
            return SetParametersResult(successful=True)
        why = self.schema.refusal(changes)
        if why:
            self.get_logger().warning(f'parameter change refused: {why}')
            return SetParametersResult(successful=False, reason=why)
        try:
            config = self.make_config(self.parameter_values(changes))
        except self.CONFIG_ERRORS as exc:
            self.get_logger().warning(f'parameter change refused: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        self._pending = config
        return SetParametersResult(successful=True)

    def _own(self, changes: list) -> bool:
        """Tell whether a change touches a parameter of the node's schema."""
        return any(p.name in self.schema.names for p in changes)

    def _apply(self, changes: list) -> None:
        if self._pending is None or not self._own(changes):
            return
        config, self._pending = self._pending, None
        if config.diagnostics_period != self.config.diagnostics_period:
            self.diag_timer.timer_period_ns = int(config.diagnostics_period * 1e9)
            self.diag_timer.reset()
        if config.status_period != self.config.status_period:
            self.status.retime(config.status_period)
        self.config = config
        names = ', '.join(p.name for p in changes)
        try:
            message = self.reconfigure(config)
        except Exception as exc:  # noqa: B902 - a post-set callback must never kill the node
            self.restart(f'applying the change of {names} failed: {exc!r}', 'reconfigured')
            self.get_logger().error(f'parameters changed ({names}) but applying them failed '
                                    f'({exc!r}); the session was restarted')
            return
        self.get_logger().info(f'parameters changed ({names}): {message}')


def parameter_values(node: Node, schema: ParameterSchema,
                     changes: Sequence[Parameter] = ()) -> dict:
    """Return the value of every parameter of schema on node, with the changes on top."""
    values = {name: node.get_parameter(name).value for name in schema.names}
    values.update({p.name: p.value for p in changes})
    return values


def diagnostic_name(node: Node) -> str:
    """
    Return the node name the /diagnostics statuses carry (and the default hardware_id).

    As diagnostic_updater's Updater (C++): the node's fully qualified name (/ns/node) if
    diagnostic_updater.use_fqn is true, else its name alone.
    """
    use_fqn = node.has_parameter(USE_FQN) and node.get_parameter(USE_FQN).value
    return node.get_fully_qualified_name() if use_fqn else node.get_name()


def link_config(config_cls: type[LinkConfig], values: dict,
                error: type[Exception]) -> LinkConfig:
    """Build a link config dataclass from parameter values (its fields); raise `error` if bad."""
    try:
        return config_cls(**{f.name: values[f.name] for f in fields(config_cls)})
    except error as exc:
        raise error(f'bad simulator parameters: {exc}') from None


class LinkSimulatorNode(Node):
    """
    A simulated link: a sensor topic, a truth topic, and a clock that starts on subscribers.

    A subclass names its parameter schema in SCHEMA (config/schema/<SCHEMA>.yaml), reads
    the parameter values in `_read(values)` into a config with `.link`, `.start_time` (s;
    0: the clock at the start) and `.wait_for_subscribers`, and names its sensor topic in
    SENSOR_TOPIC.  A change the schema refuses is refused with the reason.
    """

    SCHEMA = ''
    SENSOR_TOPIC = ''

    def __init__(self, node_name: str, *, context=None, namespace: Optional[str] = None,
                 parameter_overrides: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.schema: ParameterSchema = load_schema(self.SCHEMA)
        self.parameters_given = self.schema.declare(self)
        self.config = self._read(parameter_values(self, self.schema))
        self.add_on_set_parameters_callback(self.schema.validate)
        self.sensor_pub = self.create_publisher(Illuminance, self.SENSOR_TOPIC,
                                                SENSOR_OUTPUT_QOS)
        self.truth_pub = self.create_publisher(JointState, TRUTH_TOPIC, TRUTH_QOS)
        self.start_ns: Optional[int] = None
        self.stamp0_ns = int(round(self.config.start_time * NS))
        self.clock_watch = ClockWatch(self)

    def _read(self, values: dict) -> SimulatorSettings:
        """Build the node's config from its parameter values (subclasses)."""
        raise NotImplementedError

    def start_diagnostics(self, rate: float, count: Callable[[], int]) -> None:
        """
        Publish the 'output frequency' task and log a status line of count() samples taken.

        rate: the samples per second expected (0: any, the lockstep simulator).
        """
        params = (FrequencyParams(rate, rate, SIMULATOR_RATE_TOLERANCE) if rate > 0
                  else FrequencyParams(0.0, math.inf))
        self.frequency, self.count = FrequencyStatus(params), count
        self.diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC,
                                              DEFAULT_DEPTH)
        self.diag_timer = self.create_timer(
            self.get_parameter('diagnostic_updater.period').value, self.publish_diagnostics)
        self.status = StatusLine(self, self.get_parameter('status_period').value, count,
                                 self.status_line)

    def publish_diagnostics(self) -> DiagnosticArray:
        """Publish (and return) the 'output frequency' of the samples taken."""
        now = self.get_clock().now().nanoseconds
        self.frequency.count = self.count()
        stat = self.frequency.run(Status(OUTPUT_FREQUENCY), now)
        name = diagnostic_name(self)
        msg = conversions.diagnostics_to_msg(now, name, [stat], hardware_id=name)
        self.diag_pub.publish(msg)
        return msg

    def status_line(self, rate: float) -> str:
        """Return the INFO status line: samples per second and taken, the next stamp."""
        return (f'{rate:.3g} samples/s out, {self.count()} taken'
                + ('' if self.start_ns is not None else ', waiting for subscribers'))

    def ready(self) -> bool:
        """Return whether sample 0 may go (subclasses may add conditions)."""
        return self.sensor_pub.get_subscription_count() >= self.config.wait_for_subscribers

    def started(self, now: int) -> bool:
        """Start the stream at now once `ready()`; return whether it has started."""
        if self.start_ns is None:
            if not self.ready():
                return False
            self.start_ns = now
            if not self.stamp0_ns:
                self.stamp0_ns = now
        return True
