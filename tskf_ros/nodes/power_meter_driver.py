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

"""The power_meter_driver node: an SCPI optical power meter (Thorlabs PM100) over VISA."""

from typing import Callable, Optional

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import Illuminance
from std_srvs.srv import Trigger

from tskf_ros.core.diagnostic_status import KeyValue, Status, WARN
from tskf_ros.messages import conversions
from tskf_ros.messages import power_meter_interface as interface
from tskf_ros.messages.context import end_context
from tskf_ros.messages.diagnostic_tasks import POWER_METER
from tskf_ros.messages.power_meter_interface import (DriverConfig, MeterError, NODE_NAME,
                                                     POWER_TOPIC, SENSOR_OUTPUT_QOS)
from tskf_ros.nodes.node_base import diagnostic_name, ReconfigurableNode
from tskf_ros.nodes.node_runner import run_node
from tskf_ros.owc.meter_settings import MeterConfig
from tskf_ros.owc.power_meter import Opener, PowerMeter

SUCCESS, FAILURE, ERROR = (TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE,
                           TransitionCallbackReturn.ERROR)
# lifecycle_msgs/msg/Transition's ids -> the labels `ros2 lifecycle set` takes
TRANSITIONS = {getattr(Transition, f'TRANSITION_{name.upper()}'): name for name in (
    'configure', 'cleanup', 'activate', 'deactivate', 'unconfigured_shutdown',
    'inactive_shutdown', 'active_shutdown')}


def _built_at_configure(config: MeterConfig) -> None:
    return None


class PowerMeterDriver(ReconfigurableNode, LifecycleNode):
    """
    A managed (lifecycle) node that polls a VISA power meter and publishes its readings.

    configure: load the backend, open the resource, send the set-up commands (FAILURE if
    the backend does not load or the meter does not answer); activate: poll at `rate`
    and publish received_power (a lifecycle publisher); deactivate: stop; cleanup and
    shutdown: close the resource and the backend.  A device lost while active (I/O error,
    `max_timeouts` timeouts in a row, a failed reconnection) goes through on_error to
    unconfigured.  With `autostart` the node configures and activates itself at start and
    again after a lost device, with the reconnection backoff.
    """

    SCHEMA = NODE_NAME
    CONFIG_ERRORS = (MeterError, KeyError, TypeError)
    SESSION = staticmethod(_built_at_configure)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None,
                 opener: Optional[Opener] = None) -> None:
        # opener: tests inject faults through it (None: a pyvisa ResourceManager of backend)
        self._opener = opener
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.session: Optional[PowerMeter] = None
        self.state = 'unconfigured'
        self._lost = self._not_loaded = ''
        self._failing = False           # a failed configure was logged as an error
        self._started = not self.config.autostart   # autostart: after the first bring-up
        self._seen = (0, 0)             # (disconnects, connect failures) at the last poll
        self._said: set[str] = set()    # skip reasons logged once already
        self.pub = self.create_lifecycle_publisher(Illuminance, POWER_TOPIC, SENSOR_OUTPUT_QOS)
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.poll_timer = self.create_timer(1.0 / self.config.rate, self._tick,
                                            clock=self.steady)
        self.poll_timer.cancel()
        self.recovery_timer = self.create_timer(self.config.session.reconnect_initial,
                                                self._recover, clock=self.steady)
        self.recovery_timer.cancel()
        self.frequency = interface.readings_frequency(self.config)
        self.start_diagnostics()
        self.start_services()
        self._guard_change_state()
        if self.config.autostart:       # a backend that cannot load ends the start here
            try:
                self._bring_up(at_start=True)
            except Exception:  # noqa: B902 - see _guarded
                if self.context.ok():
                    raise
                # Ctrl-C during the start: run_node ends it as an interrupt (exit 0)
                raise KeyboardInterrupt from None
        self.get_logger().info(
            f'driver of {self.config.session.resource} through {self.config.session.backend} '
            f'at {self.config.rate:g} Hz on {self.resolve_topic_name(POWER_TOPIC)}; '
            + (f'{self.state} (autostart)' if self.config.autostart
               else 'unconfigured: waiting for ~/change_state'))

    def _now(self) -> int:
        return self.get_clock().now().nanoseconds

    def make_config(self, values: dict) -> DriverConfig:
        """Build the config from parameter values (MeterError if bad)."""
        return interface.make_config(values)

    # -- lifecycle transitions -------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the backend, open the meter and send the set-up commands."""
        self.recovery_timer.cancel()
        if self.session is None:
            try:
                self.session = PowerMeter(self.config.session, opener=self._opener,
                                          clock=self._now)
            except MeterError as exc:
                self._not_loaded = str(exc)
                if self._started:           # else the start ends with this line
                    self.get_logger().error(f'configure failed: {exc}')
                return FAILURE
        if not (self.session.connected or self.session.connect()):
            self._report_failure('configure failed')
            return FAILURE
        self.get_logger().info(f'connected to {self.session.identity or "the meter"} '
                               f'({self.config.session.resource})')
        self._failing = False
        self.state = 'inactive'
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start polling and publishing."""
        super().on_activate(state)
        self._seen = self._counts()
        self.poll_timer.reset()
        self.state = 'active'
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop polling and publishing (ERROR when called for a lost device)."""
        self.poll_timer.cancel()
        super().on_deactivate(state)
        self.state = 'inactive'
        return ERROR if self._lost else SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the resource and the backend."""
        self._close()
        self.state = 'unconfigured'
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop and close everything."""
        self.pub.on_deactivate(state)
        self._close()
        self.state = 'finalized'
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the lost device; unconfigured (autostart: configure again after the backoff)."""
        why, self._lost = self._lost or f'a transition from {state.label} failed', ''
        self.poll_timer.cancel()
        self.pub.on_deactivate(state)
        if self.session is not None and self.session.connected:
            self.session.disconnect(why)
        self.state = 'unconfigured'
        then = (f'configuring again in {self._retry_delay():.3g} s' if self.config.autostart
                else 'unconfigured until ~/change_state configures it again')
        self.get_logger().error(f'device lost ({why}): {then}')
        if self.config.autostart:
            self._schedule_recovery()
        return SUCCESS

    def _guard_change_state(self) -> None:
        """
        Answer a ~/change_state request that is no transition from the state with a failure.

        rclpy's lifecycle service lets rcl's refusal ("Transition is not registered")
        escape the executor, which ends the process; rclcpp answers success = false and
        stays up, and so does this node, with one warning line.  The state machine has not
        moved when rcl refuses: nothing is undone.
        """
        for service in self.services:
            if service.srv_name.endswith('/change_state'):
                service.callback = self._change_state_or_refuse(service.callback)

    def _change_state_or_refuse(self, callback: Callable) -> Callable:
        def change_state(request: ChangeState.Request,
                         response: ChangeState.Response) -> ChangeState.Response:
            before = self.state
            try:
                return callback(request, response)
            except RuntimeError as exc:     # rclpy's RCLError
                if not self.context.ok():
                    raise
                t = request.transition
                name = t.label or TRANSITIONS.get(t.id, f'transition {t.id}')
                self.get_logger().warning(
                    f'~/change_state refused: {name} is not a transition from {before} '
                    f'({str(exc).split(",")[0]})')
                response.success = False
                return response
        return change_state

    # -- autostart ---------------------------------------------------------------------------

    def _bring_up(self, at_start: bool = False) -> None:
        configured = self.trigger_configure() == SUCCESS
        self._started = True
        if configured:
            self.trigger_activate()
        elif at_start and self.session is None:
            raise MeterError(self._not_loaded)     # the backend cannot load: cannot start
        else:
            self._schedule_recovery()

    def _recover(self) -> None:
        self.recovery_timer.cancel()
        if self.state == 'unconfigured':
            self._guarded(self._bring_up)

    def _guarded(self, callback: Callable[[], None]) -> None:
        """Run a callback that talks to the meter; a Ctrl-C during its VISA call ends quietly."""
        # SIGINT (SIGTERM) shuts the context down while a query blocks; when it returns,
        # anything of rcl raises (publish, a lifecycle transition), or KeyboardInterrupt
        # lands in the query: either escaping a callback is a FATAL line and a stack
        try:
            callback()
        except KeyboardInterrupt:
            end_context(self.context)
        except Exception:  # noqa: B902 - the node is ending, not failing
            if self.context.ok():
                raise

    def _retry_delay(self) -> float:
        return self.session.retry_delay() if self.session is not None \
            else self.config.session.reconnect_initial

    def _schedule_recovery(self) -> None:
        self.recovery_timer.timer_period_ns = int(round(self._retry_delay() * 1e9))
        self.recovery_timer.reset()

    def _report_failure(self, what: str) -> None:
        retry = (f'retrying in {self._retry_delay():.3g} s' if self.config.autostart
                 else 'configure again to retry')
        text = f'{what}: {self.session.last_error}; {retry}'
        if not self._failing:
            self._failing = True
            self.get_logger().error(text)
        else:
            self.get_logger().warning(text, throttle_duration_sec=10.0)

    def _close(self) -> None:
        self.poll_timer.cancel()
        self.recovery_timer.cancel()
        if self.session is not None:
            self.session.close()
        self.session = None

    # -- reading -----------------------------------------------------------------------------

    def _counts(self) -> tuple[int, int]:
        return (self.session.disconnects, self.session.connect_failures) \
            if self.session is not None else (0, 0)

    def _tick(self) -> None:
        self._guarded(self._poll)

    def _poll(self) -> None:
        was_connected = self.session.connected
        reading = self.session.poll()
        if reading is not None:
            self.pub.publish(interface.reading_to_msg(reading, self.config))
        self._say_skips_once()
        if self._counts() != self._seen:       # the device is lost (not a requested restart)
            self._lost = self.session.last_error
            self.trigger_deactivate()          # ERROR: on to on_error
            return
        if self.session.connected and not was_connected:
            self.get_logger().info(f'connected to {self.session.identity or "the meter"} '
                                   f'({self.config.session.resource})')

    def _say_skips_once(self) -> None:
        for reason, count in self.session.skipped.items():
            if count and reason not in self._said:
                self._said.add(reason)
                self.get_logger().warning(
                    f'{self.session.last_error}: not published; such readings are counted '
                    f'in /diagnostics (skipped_{reason}), this is said once')

    # -- parameters, services, diagnostics ----------------------------------------------------

    def reconfigure(self, config: DriverConfig) -> str:
        """Retime the poll timer and hand the meter its new settings."""
        self.frequency.params = interface.readings_frequency(config).params
        period_ns = int(round(1e9 / config.rate))
        if period_ns != self.poll_timer.timer_period_ns:
            self.poll_timer.timer_period_ns = period_ns
            if not self.poll_timer.is_canceled():
                self.poll_timer.reset()
        if self.session is None:
            return 'applied at the next configure'
        return self.session.reconfigure(config.session)

    def _on_reset(self, request: Trigger.Request,
                  response: Trigger.Response) -> Trigger.Response:
        if self.session is None or self.state not in ('inactive', 'active'):
            response.success = False
            response.message = (f'no session to restart: the driver is {self.state} '
                                '(configure it first)')
            self.get_logger().warning(f'~/reset refused: {response.message}')
            return response
        return super()._on_reset(request, response)

    def restart(self, why: str, reason: str = 'service') -> None:
        """Close the connection and reconnect at the next poll."""
        if self.session is not None:
            self.session.restart(why)
        self.get_logger().warning(f'reconnecting: {why}')

    def diagnostics_message(self, stamp_ns: int):
        """Return the meter's /diagnostics message, its lifecycle state in the message."""
        if self.session is None:
            idle = Status(POWER_METER, WARN, f'{self.state}: not reading',
                          [KeyValue('Lifecycle state', self.state)])
            return conversions.diagnostics_to_msg(stamp_ns, diagnostic_name(self), [idle],
                                                  hardware_id=self.config.session.resource)
        msg = interface.diagnostics_message(self.session, self.config, stamp_ns,
                                            self.frequency, node_name=diagnostic_name(self))
        if self.state != 'active':
            for status in msg.status:
                status.message = f'{self.state}: {status.message}'
        return msg

    def status_count(self) -> int:
        """Return the readings published so far (the status line's rate counts them)."""
        return self.session.published if self.session is not None else 0

    def status_line(self, rate: float) -> str:
        """Return the INFO status line: readings per second, published, skipped."""
        if self.session is None:
            return f'{self.state}: not reading'
        return interface.status_line(self.session, rate)

    def destroy_node(self) -> None:
        """Close the VISA resource and backend, then the node."""
        self._close()
        super().destroy_node()


DESCRIPTION = ('Optical power meter driver (Thorlabs PM100 or any SCPI meter) over VISA, a '
               'lifecycle node: publishes received_power as power_meter_simulator does. '
               'Parameters: --ros-args --params-file config/power_meter_driver.yaml or '
               '-p name:=value; simulated meter: -p backend:=<share>/config/pm100_sim.yaml@sim;'
               ' -p autostart:=false leaves configure and activate to a lifecycle manager')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(PowerMeterDriver, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(MeterError,), args=args)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
