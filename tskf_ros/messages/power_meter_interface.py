"""The power_meter_driver's interface: parameters, config, reading and diagnostics messages."""

from dataclasses import dataclass, fields

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterType
from sensor_msgs.msg import Illuminance

from tskf_ros.core.diagnostic_status import (FrequencyParams, FrequencyStatus, LEVEL_NAMES,
                                             Status)
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import POWER_TOPIC
from tskf_ros.messages.parameters import descriptor
from tskf_ros.messages.qos import SENSOR_OUTPUT_QOS
from tskf_ros.owc.meter_settings import (MeterConfig, MeterError, Reading, ScpiCommands,
                                         UNITS)
from tskf_ros.owc.power_meter import PowerMeter

__all__ = ['DriverConfig', 'declare_all', 'default_parameters', 'diagnostics_message',
           'make_config', 'MeterError', 'NODE_NAME', 'PARAMETERS', 'POWER_TOPIC',
           'reading_to_msg', 'SENSOR_OUTPUT_QOS']

NODE_NAME = 'power_meter_driver'
# name -> (description, (lo, hi) or None, read-only); defaults are MeterConfig's and below
METER_HELP = {
    'resource': ('VISA resource name: USB0::0x1313::0x8078::<serial>::INSTR (PM100D), '
                 'TCPIP0::<host>::INSTR, ASRL/dev/ttyUSB0::INSTR', None, True),
    'backend': ("pyvisa backend: '@py' (pyvisa-py, real devices), "
                "'<path>/pm100_sim.yaml@sim' (pyvisa-sim)", None, True),
    'unit': ('unit the meter is set to: ' + ' | '.join(UNITS) + ' (published in mW '
             'whatever it is)', None, False),
    'wavelength': ('nm: calibration wavelength of the sensor', (1.0, 1e6), False),
    'averaging': ('samples the meter averages per reading (PM100: about 3 ms each)', None,
                  False),
    'timeout': ('s: one query; a reading that takes longer is skipped', (1e-3, 60.0), False),
    'max_power': ('mW: a reading above is refused (over-range)', (1e-12, 1e12), False),
    'max_timeouts': ('timeouts in a row that mean the device is gone (reconnect)', None,
                     False),
    'reconnect_initial': ('s: first retry after a failed connection; doubles per failure',
                          (1e-3, 3600.0), False),
    'reconnect_max': ('s: the cap of the retry delay', (1e-3, 3600.0), False),
    'unit_check_every': ('query the unit before every n-th reading (1: each); 0: never',
                         None, False),
}
COMMAND_HELP = {
    'identify': 'identification query, logged and in diagnostics',
    'clear_status': 'clear the status and error queue at connection',
    'set_unit': 'set the unit; {unit} is W, MW or DBM',
    'unit_query': 'query the unit (W, MW, UW, NW or DBM); empty: trust set_unit',
    'set_wavelength': 'set the wavelength; {wavelength} is in nm',
    'set_averaging': 'set the averaging count; {averaging}',
    'configure': 'put the meter into power measurement',
    'read': 'query one power reading',
    'error_query': "read the error queue after configuring, until '0,...'",
}
NODE_HELP = {
    'rate': ('Hz: readings per second (a steady-clock timer: the device runs in real time)',
             (1e-3, 1e4), False),
    'frame_id': ('header.frame_id of received_power (the simulator uses power_meter)', None,
                 False),
    'variance': ('mW^2: variance published with every reading; 0: unknown', (0.0, 1e12),
                 False),
    'diagnostic_updater.period': ("s between /diagnostics messages (as diagnostic_updater's)",
                                  (0.01, 3600.0), False),
    'status_period': ('s between two INFO status lines in the log; 0: none', (0.0, 1e6),
                      False),
}
NODE_DEFAULTS = {'rate': 1.0, 'frame_id': 'power_meter', 'variance': 0.0,
                 'diagnostic_updater.period': 1.0, 'status_period': 10.0}
# the readings' frequency is WARN outside rate * (1 -/+ this)
RATE_TOLERANCE = 0.5
PARAMETERS = tuple(METER_HELP) + tuple(f'scpi_{c}' for c in COMMAND_HELP) + tuple(NODE_HELP)
TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
         float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}


@dataclass(frozen=True)
class DriverConfig:
    """The node's settings, read once: the meter's and the node's own."""

    session: MeterConfig
    rate: float
    frame_id: str
    variance: float
    diagnostics_period: float        # the parameter diagnostic_updater.period
    status_period: float = 10.0      # s between two INFO status lines; 0: none


def default_parameters() -> dict:
    """Return the default of every parameter."""
    meter, commands = MeterConfig(), ScpiCommands()
    values = {name: getattr(meter, name) for name in METER_HELP}
    values.update({f'scpi_{c}': getattr(commands, c) for c in COMMAND_HELP})
    values.update(NODE_DEFAULTS)
    return values


def declare_all(node) -> None:
    """Declare every parameter of the driver on node, with its descriptor."""
    help_ = {**METER_HELP, **NODE_HELP,
             **{f'scpi_{c}': (f"SCPI: {text} ('': skip)", None, False)
                for c, text in COMMAND_HELP.items()}}
    help_['scpi_read'] = ('SCPI: ' + COMMAND_HELP['read'], None, False)
    for name, value in default_parameters().items():
        text, rng, read_only = help_[name]
        node.declare_parameter(name, value, descriptor(text, rng, TYPES[type(value)],
                                                       read_only=read_only))


def make_config(values: dict) -> DriverConfig:
    """Build the config from parameter values; raise MeterError with the reason if bad."""
    for name, default in default_parameters().items():
        if type(values[name]) is not type(default):
            raise MeterError(f'{name} must be a {type(default).__name__}, got '
                             f'{values[name]!r}')
    commands = ScpiCommands(**{f.name: values[f'scpi_{f.name}'] for f in fields(ScpiCommands)})
    meter = MeterConfig(commands=commands, **{name: values[name] for name in METER_HELP})
    if not values['rate'] > 0 or not values['diagnostic_updater.period'] > 0 \
            or not values['variance'] >= 0 or not values['status_period'] >= 0:
        raise MeterError('rate and diagnostic_updater.period must be > 0, variance and '
                         'status_period >= 0')
    return DriverConfig(meter, values['rate'], values['frame_id'], values['variance'],
                        values['diagnostic_updater.period'], values['status_period'])


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
    device = Status('power meter', LEVEL_NAMES.index(level), message)
    for key, value in values.items():
        device.add(key, value)
    return conversions.diagnostics_to_msg(
        stamp_ns, node_name, [frequency.run(Status('output frequency'), stamp_ns), device],
        hardware_id=config.session.resource)


def status_line(meter: PowerMeter, rate: float) -> str:
    """Return the one-line status the node logs: readings per second, published, skipped."""
    return (f'{rate:.3g} readings/s, {meter.published} published, '
            f'{sum(meter.skipped.values())} skipped, '
            f'{"connected" if meter.connected else "not connected"}'
            + (f'; last error: {meter.last_error}' if meter.last_error else ''))
