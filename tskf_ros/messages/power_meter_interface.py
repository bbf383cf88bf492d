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

"""The power_meter_driver's interface: parameters, config, reading and diagnostics messages."""

from dataclasses import dataclass, fields

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Illuminance

from tskf_ros.core.diagnostic_status import (FrequencyParams, FrequencyStatus, LEVEL_NAMES,
                                             Status)
from tskf_ros.messages import conversions
from tskf_ros.messages.diagnostic_tasks import OUTPUT_FREQUENCY, POWER_METER
from tskf_ros.messages.estimator_interface import POWER_TOPIC
from tskf_ros.messages.parameter_schema import load_schema, ParameterError
from tskf_ros.messages.qos import SENSOR_OUTPUT_QOS
from tskf_ros.owc.meter_settings import MeterConfig, MeterError, Reading, ScpiCommands
from tskf_ros.owc.power_meter import PowerMeter

__all__ = ['DriverConfig', 'default_parameters', 'diagnostics_message', 'make_config',
           'MeterError', 'NODE_NAME', 'parameter_names', 'POWER_TOPIC',
           'reading_to_msg', 'SENSOR_OUTPUT_QOS']

NODE_NAME = 'power_meter_driver'
# the readings' frequency is WARN outside rate * (1 -/+ this)
RATE_TOLERANCE = 0.5


@dataclass(frozen=True)
class DriverConfig:
    """The node's settings, read once: the meter's and the node's own."""

    session: MeterConfig
    rate: float
    frame_id: str
    variance: float
    diagnostics_period: float        # the parameter diagnostic_updater.period
    status_period: float = 10.0      # s between two INFO status lines; 0: none
    autostart: bool = True


def default_parameters() -> dict:
    """Return the default of every parameter (config/schema/power_meter_driver.yaml)."""
    return load_schema(NODE_NAME).defaults()


def parameter_names() -> tuple:
    """Return the names of the driver's parameters, in the schema's order."""
    return load_schema(NODE_NAME).names


def make_config(values: dict) -> DriverConfig:
    """Build the config from parameter values; raise MeterError with the reason if bad."""
    try:
        values = load_schema(NODE_NAME).check(values)
    except ParameterError as exc:
        raise MeterError(str(exc)) from None
    commands = ScpiCommands(**{f.name: values[f'scpi_{f.name}'] for f in fields(ScpiCommands)})
    meter = MeterConfig(commands=commands, **{f.name: values[f.name] for f in fields(MeterConfig)
                                              if f.name != 'commands'})
    if not values['rate'] > 0 or not values['diagnostic_updater.period'] > 0 \
            or not values['variance'] >= 0 or not values['status_period'] >= 0:
        raise MeterError('rate and diagnostic_updater.period must be > 0, variance and '
                         'status_period >= 0')
    return DriverConfig(meter, values['rate'], values['frame_id'], values['variance'],
                        values['diagnostic_updater.period'], values['status_period'],
                        values['autostart'])


def reading_to_msg(reading: Reading, config: DriverConfig) -> Illuminance:
    """Return the received_power message of a reading, as the simulator builds it."""
    return conversions.power_to_msg(reading.stamp_ns, reading.power_mw, config.variance,
                                    frame_id=config.frame_id)


def readings_frequency(config: DriverConfig) -> FrequencyStatus:
    """Return the FrequencyStatus of the readings published, expected at config.rate."""
    return FrequencyStatus(FrequencyParams(config.rate, config.rate, RATE_TOLERANCE))


def diagnostics_message(meter: PowerMeter, config: DriverConfig, stamp_ns: int,
                        frequency: FrequencyStatus, *,
                        node_name: str = NODE_NAME) -> DiagnosticArray:
    """Return the /diagnostics message: 'output frequency' and 'power meter' at stamp_ns."""
    level, message, values = meter.diagnostics()
    frequency.count = meter.published
    device = Status(POWER_METER, LEVEL_NAMES.index(level), message)
    for key, value in values.items():
        device.add(key, value)
    return conversions.diagnostics_to_msg(
        stamp_ns, node_name, [frequency.run(Status(OUTPUT_FREQUENCY), stamp_ns), device],
        hardware_id=config.session.resource)


def status_line(meter: PowerMeter, rate: float) -> str:
    """Return the one-line status the node logs: readings per second, published, skipped."""
    return (f'{rate:.3g} readings/s, {meter.published} published, '
            f'{sum(meter.skipped.values())} skipped, '
            f'{"connected" if meter.connected else "not connected"}'
            + (f'; last error: {meter.last_error}' if meter.last_error else ''))
