"""The power_meter_driver node: an SCPI optical power meter (Thorlabs PM100) over VISA."""

from functools import partial
from typing import Optional

from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import Illuminance

from tskf_ros.messages import power_meter_interface as interface
from tskf_ros.messages.power_meter_interface import (DriverConfig, MeterError, NODE_NAME,
                                                     POWER_TOPIC, SENSOR_OUTPUT_QOS)
from tskf_ros.nodes.node_base import ReconfigurableNode, run_node
from tskf_ros.owc.power_meter import Opener, PowerMeter


class PowerMeterDriver(ReconfigurableNode):
    """Poll a VISA power meter at `rate`, publish its valid readings on received_power."""

    PARAMETERS = interface.PARAMETERS
    CONFIG_ERRORS = (MeterError, KeyError, TypeError)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None,
                 opener: Optional[Opener] = None) -> None:
        # the meter is built by ReconfigurableNode from config.session; opener: tests inject
        # faults through it (None: a pyvisa ResourceManager of the backend parameter)
        self.SESSION = partial(PowerMeter, opener=opener, clock=self._now)
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.pub = self.create_publisher(Illuminance, POWER_TOPIC, SENSOR_OUTPUT_QOS)
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.poll_timer = self.create_timer(1.0 / self.config.rate, self._tick,
                                            clock=self.steady)
        self.frequency = interface.readings_frequency(self.config)
        self.start_diagnostics()
        self.start_services()
        self._was_connected, self._failures_seen = False, 0
        self.get_logger().info(
            f'reading {self.config.session.resource} through {self.config.session.backend} '
            f'at {self.config.rate:g} Hz, publishing {self.resolve_topic_name(POWER_TOPIC)}')

    def _now(self) -> int:
        return self.get_clock().now().nanoseconds

    def _declare(self) -> None:
        interface.declare_all(self)

    def make_config(self, values: dict) -> DriverConfig:
        """Build the config from parameter values (MeterError if bad)."""
        return interface.make_config(values)

    def reconfigure(self, config: DriverConfig) -> str:
        """Retime the poll timer and hand the meter its new settings."""
        self.frequency.params = interface.readings_frequency(config).params
        period_ns = int(round(1e9 / config.rate))
        if period_ns != self.poll_timer.timer_period_ns:
            self.poll_timer.timer_period_ns = period_ns
            self.poll_timer.reset()
        return self.session.reconfigure(config.session)

    def restart(self, why: str, reason: str = 'service') -> None:
        """Close the connection and reconnect at the next poll."""
        self.session.restart(why)
        self.get_logger().warning(f'reconnecting: {why}')

    def diagnostics_message(self, stamp_ns: int):
        """Return the meter's /diagnostics message."""
        return interface.diagnostics_message(self.session, self.config, stamp_ns,
                                             self.frequency, node_name=self.get_name())

    def status_count(self) -> int:
        """Return the readings published so far (the status line's rate counts them)."""
        return self.session.published

    def status_line(self, rate: float) -> str:
        """Return the INFO status line: readings per second, published, skipped."""
        return interface.status_line(self.session, rate)

    def _tick(self) -> None:
        reading = self.session.poll()
        if reading is not None:
            self.pub.publish(interface.reading_to_msg(reading, self.config))
        connected = self.session.connected
        if connected != self._was_connected:
            if connected:
                self.get_logger().info(f'connected to {self.session.identity or "the meter"}'
                                       f' ({self.config.session.resource})')
            else:
                self.get_logger().error(f'{self.session.last_error}; retrying in '
                                        f'{self.session.retry_delay():.3g} s')
        elif self.session.connect_failures != self._failures_seen:
            self.get_logger().warning(f'{self.session.last_error}; retrying in '
                                      f'{self.session.retry_delay():.3g} s',
                                      throttle_duration_sec=10.0)
        self._was_connected, self._failures_seen = connected, self.session.connect_failures

    def destroy_node(self) -> None:
        """Close the VISA resource and backend, then the node."""
        self.session.close()
        super().destroy_node()


DESCRIPTION = ('Optical power meter driver (Thorlabs PM100 or any SCPI meter) over VISA: '
               'publishes received_power as power_meter_simulator does. Parameters: '
               '--ros-args --params-file config/power_meter_driver.yaml or -p name:=value; '
               'simulated meter: -p backend:=<share>/config/pm100_sim.yaml@sim')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(PowerMeterDriver, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(MeterError,), args=args)


if __name__ == '__main__':
    main()
