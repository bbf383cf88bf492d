"""
power_meter: a real optical power meter (Thorlabs PM100 or any SCPI meter) over VISA.

No ROS here: the node tskf_ros.nodes.power_meter_driver calls `PowerMeter.poll()` on a
timer and publishes what it returns.  The meter is driven by plain SCPI strings (the
PM100's by default, each a parameter) through pyvisa:

    connect:  *IDN?  *CLS  SENS:POW:UNIT W  SENS:CORR:WAV 1550  SENS:AVER:COUN 1  CONF:POW
              then SYST:ERR? until '0,...' (the errors are reported, not fatal)
    read:     SENS:POW:UNIT? (every unit_check_every readings)  MEAS:POW?

Stamping.  A reading is stamped at the midpoint of its query, in the stamping clock (the
node's clock): t = t_write + (t_read - t_write) / 2, where t_write is read just before the
query is written and t_read just after its reply has arrived.  The meter takes the reading
somewhere in between (after the command arrives, before the reply leaves); with equal
transfer times each way the midpoint is right, and it is never wrong by more than half the
round trip, `latency = t_read - t_write`, which the diagnostics publish (last, mean, max).
The PM100 averages `averaging` samples of about 3 ms before it answers: the midpoint then
also lands near the middle of the averaging window, which is the time the mean belongs to.

Faults (each counted; see `SKIP_REASONS` and `PowerMeter.diagnostics`):

- device absent or failing to configure: stay disconnected, retry after
  reconnect_initial, 2x, 4x ... seconds, capped at reconnect_max;
- a read timeout: that reading is skipped ('timeout') and the device cleared (a late
  reply must not be taken for the next one); `max_timeouts` in a row count as a lost
  device;
- any other I/O error (cable pulled): close, reconnect with the backoff above;
- a reading that is not a power: the SCPI overflow sentinels (|v| >= 9.9E37: 'overflow'),
  NaN or inf ('not_finite'), negative in a linear unit ('negative'), above max_power
  ('above_max'), not a number ('unparseable'): skipped;
- a unit other than the configured one: W, mW and dBm convert to mW without ambiguity,
  so a reading in any of them is converted (and counted as 'unit_converted'); a unit
  the driver does not know is refused ('wrong_unit').  The unit is the one the reply
  names ('1.2E-3 W'), else the last answer to the unit query;
- a stamping clock that reads 0 (use_sim_time before the first /clock): the reading is
  skipped ('no_clock'), since a zero stamp means 'unset'.
"""

from collections import deque
from dataclasses import dataclass, field, fields, replace
import math
import time
from typing import Callable, Optional, Protocol

import pyvisa
from pyvisa import rname
from pyvisa.constants import StatusCode
from pyvisa.resources import MessageBasedResource

from tskf_ros.core.units import NS

__all__ = ['DEFAULT_RESOURCE', 'MeterConfig', 'MeterError', 'Opener', 'PowerMeter',
           'Reading', 'Resource', 'ScpiCommands', 'SKIP_REASONS', 'to_milliwatts',
           'UNITS', 'VisaOpener']

# the simulated PM100D of config/pm100_sim.yaml; a real one: USB0::0x1313::0x8078::<serial>
DEFAULT_RESOURCE = 'USB0::0x1313::0x8078::P0000000::INSTR'
# SCPI unit word -> mW per unit ('MW' is milliwatt: SCPI suffixes are case-blind, M = milli)
LINEAR_UNITS = {'W': 1e3, 'MW': 1.0, 'UW': 1e-3, 'NW': 1e-6}
DBM = 'DBM'
UNITS = {'W': 'W', 'mW': 'MW', 'dBm': DBM}      # the unit parameter -> its SCPI word
# SCPI's overflow (+-9.9E37) and not-a-number (9.91E37) sentinels
SCPI_OVERFLOW = 9.9e37
# why a reading was not published; 'no_clock': the stamping clock read 0 (a node on
# use_sim_time before /clock arrives), a stamp the estimator would reject
SKIP_REASONS = ('timeout', 'overflow', 'not_finite', 'negative', 'above_max', 'unparseable',
                'wrong_unit', 'no_clock')
# the error-queue reply that means 'empty' starts with this code
NO_ERROR = '0'
MAX_ERRORS_READ = 20


class MeterError(ValueError):
    """A power-meter setting that cannot work (bad resource name, command template, range)."""


@dataclass(frozen=True)
class ScpiCommands:
    """The SCPI strings, the PM100's by default; '' leaves a step out."""

    identify: str = '*IDN?'
    clear_status: str = '*CLS'
    set_unit: str = 'SENS:POW:UNIT {unit}'
    unit_query: str = 'SENS:POW:UNIT?'
    set_wavelength: str = 'SENS:CORR:WAV {wavelength:g}'
    set_averaging: str = 'SENS:AVER:COUN {averaging:d}'
    configure: str = 'CONF:POW'
    read: str = 'MEAS:POW?'
    error_query: str = 'SYST:ERR?'


@dataclass(frozen=True)
class MeterConfig:
    """What to open, how to set it up, how to judge its readings, how to retry."""

    resource: str = DEFAULT_RESOURCE
    backend: str = '@py'
    unit: str = 'W'                 # W | mW | dBm, the unit the meter is set to
    wavelength: float = 1550.0      # nm, the sensor's calibration wavelength
    averaging: int = 1              # samples the meter averages per reading
    timeout: float = 1.0            # s, one query
    max_power: float = 1e4          # mW, a reading above is refused
    max_timeouts: int = 3           # timeouts in a row that mean the device is gone
    reconnect_initial: float = 0.5  # s, first retry delay; doubles per failure
    reconnect_max: float = 30.0     # s, the cap of the retry delay
    unit_check_every: int = 1       # query the unit before every n-th reading; 0: never
    commands: ScpiCommands = field(default_factory=ScpiCommands)

    def __post_init__(self) -> None:
        try:
            rname.parse_resource_name(self.resource)
        except rname.InvalidResourceName as exc:
            raise MeterError(f'resource {self.resource!r} is not a VISA resource name '
                             f'({exc})') from None
        if self.unit not in UNITS:
            raise MeterError(f'unit must be one of {", ".join(UNITS)}, got {self.unit!r}')
        checks = {'wavelength': self.wavelength > 0, 'averaging': self.averaging >= 1,
                  'timeout': self.timeout > 0, 'max_power': self.max_power > 0,
                  'max_timeouts': self.max_timeouts >= 1,
                  'reconnect_initial': self.reconnect_initial > 0,
                  'reconnect_max': self.reconnect_max >= self.reconnect_initial,
                  'unit_check_every': self.unit_check_every >= 0}
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise MeterError(f'out of range: {", ".join(f"{n}={getattr(self, n)!r}" for n in bad)}'
                             ' (reconnect_max must be >= reconnect_initial)')
        if not self.commands.read:
            raise MeterError('the read command is empty')
        for f in fields(ScpiCommands):
            self.command(f.name)

    def command(self, name: str) -> str:
        """Return the command `name` with {unit}, {wavelength} and {averaging} filled in."""
        template = getattr(self.commands, name)
        try:
            return template.format(unit=UNITS[self.unit], wavelength=self.wavelength,
                                   averaging=self.averaging)
        except (KeyError, IndexError, ValueError) as exc:
            raise MeterError(f'command {name} {template!r}: {exc!r} (fields: {{unit}}, '
                             '{wavelength}, {averaging})') from None


class Resource(Protocol):
    """What the meter needs of an open VISA message-based resource (pyvisa's)."""

    def write(self, message: str) -> int: ...

    def query(self, message: str) -> str: ...

    def clear(self) -> None: ...

    def close(self) -> None: ...


class Opener(Protocol):
    """Opens resources of one backend; `close()` releases the backend."""

    def open_resource(self, resource: str, timeout_ms: int) -> Resource: ...

    def close(self) -> None: ...


class VisaOpener:
    """Open resources through a pyvisa ResourceManager of `backend` ('@py', 'file.yaml@sim')."""

    def __init__(self, backend: str) -> None:
        try:
            self.manager = pyvisa.ResourceManager(backend)
        except (OSError, ValueError, pyvisa.errors.Error) as exc:
            # pyvisa-sim folds a whole traceback into its message, its newlines escaped:
            # keep its last line (the cause)
            text = str(exc).replace('\\n', '\n').replace("\\'", "'")
            lines = [line.strip() for line in text.splitlines() if line.strip('\'" ')]
            cause = lines[-1] if lines else type(exc).__name__
            raise MeterError(f'VISA backend {backend!r} cannot be loaded: {cause}') from None

    def open_resource(self, resource: str, timeout_ms: int) -> Resource:
        """Open a message-based resource with newline termination."""
        opened = self.manager.open_resource(resource, read_termination='\n',
                                            write_termination='\n', timeout=timeout_ms)
        if not isinstance(opened, MessageBasedResource):
            opened.close()
            raise MeterError(f'{resource} is not a message-based (SCPI) instrument')
        return opened

    def close(self) -> None:
        """Close the ResourceManager (and every resource still open in it)."""
        self.manager.close()


# what an instrument's I/O raises: pyvisa's errors, the OS's (USB, sockets), and pyvisa-py's
# ValueError('No device found.') for a USB device that is not there
IO_ERRORS = (pyvisa.errors.Error, OSError, ValueError, NotImplementedError)


@dataclass(frozen=True)
class Reading:
    """One published reading: stamp (ns, stamping clock), power (mW), query latency (ns)."""

    stamp_ns: int
    power_mw: float
    latency_ns: int


def parse_unit(word: str) -> Optional[str]:
    """Return the SCPI unit word of a reply ('w', 'dBm' -> 'W', 'DBM'), None if unknown."""
    w = word.strip().upper()
    return w if w in LINEAR_UNITS or w == DBM else None


def to_milliwatts(reply: str, unit: Optional[str], max_power: float
                  ) -> tuple[Optional[float], str, Optional[str]]:
    """
    Return (power mW, '', unit) for a valid reply, else (None, reason, unit).

    `unit` is the SCPI unit word the meter last reported (None: unknown); a unit the reply
    names after the number ('1.2E-3 W') takes precedence.  The unit returned is the one
    the value was read in; the reason is one of SKIP_REASONS.
    """
    parts = reply.split()
    if len(parts) == 2:
        unit = parse_unit(parts[1])
    try:
        if not 1 <= len(parts) <= 2:
            raise ValueError(reply)
        value = float(parts[0])
    except ValueError:
        return None, 'unparseable', unit
    if not math.isfinite(value):
        return None, 'not_finite', unit
    if abs(value) >= SCPI_OVERFLOW:
        return None, 'overflow', unit
    if unit is None:
        return None, 'wrong_unit', unit
    if unit == DBM:
        # P [mW] = 10^(P [dBm] / 10): any finite dBm is a positive power
        if value > 10 * math.log10(max_power):
            return None, 'above_max', unit
        return 10.0 ** (value / 10.0), '', unit
    if value < 0:
        return None, 'negative', unit
    mw = value * LINEAR_UNITS[unit]
    if mw > max_power:
        return None, 'above_max', unit
    return mw, '', unit


class PowerMeter:
    """
    One power meter: connect (with backoff), read, validate, stamp; count what goes wrong.

    `opener` opens resources (a VisaOpener of config.backend by default; tests pass one
    that injects faults).  `clock()` is the stamping clock (ns); `monotonic()` (s) times
    the retries and the latency statistics.  Nothing here blocks longer than one query
    (config.timeout), and `poll()` never raises for what a device does.
    """

    def __init__(self, config: MeterConfig, *, opener: Optional[Opener] = None,
                 clock: Callable[[], int] = time.time_ns,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.opener = opener if opener is not None else VisaOpener(config.backend)
        self.clock, self.monotonic = clock, monotonic
        self.resource: Optional[Resource] = None
        self.identity = ''
        self.device_unit: Optional[str] = None
        self.device_errors: list[str] = []
        self.last_error = ''
        self.failures = 0                      # connection attempts failed in a row
        self.next_attempt = monotonic()        # when the next connection attempt is due
        self.consecutive_timeouts = 0
        self.reads = 0
        self.published = 0
        self.skipped = dict.fromkeys(SKIP_REASONS, 0)
        self.unit_converted = 0
        self.connects = self.disconnects = self.connect_failures = 0
        self.latency_ns: deque = deque(maxlen=100)
        self._window: tuple[float, int, int, int] = (monotonic(), 0, 0, 0)

    @property
    def connected(self) -> bool:
        """Whether a resource is open and configured."""
        return self.resource is not None

    def retry_delay(self) -> float:
        """Return the delay before the next attempt: initial * 2^(failures - 1), capped."""
        c = self.config
        return min(c.reconnect_initial * 2.0 ** max(self.failures - 1, 0), c.reconnect_max)

    def poll(self) -> Optional[Reading]:
        """Connect if due, else take one reading; return it if it is to be published."""
        if self.resource is None:
            if self.monotonic() >= self.next_attempt:
                self.connect()
            return None
        return self.read()

    def connect(self) -> bool:
        """Open and configure the device; on failure schedule the next attempt."""
        c = self.config
        try:
            self.resource = self.opener.open_resource(c.resource, int(round(c.timeout * 1000)))
            self.identity = self.resource.query(c.command('identify')).strip() \
                if c.commands.identify else ''
            if c.commands.identify and not self.identity:
                raise ValueError(f'no answer to {c.command("identify")}: not a meter')
            self.configure()
        except IO_ERRORS as exc:
            self._drop(f'cannot connect to {c.resource}: {describe(exc)}')
            self.connect_failures += 1
            return False
        self.failures = 0
        self.consecutive_timeouts = 0
        self.connects += 1
        return True

    def _device(self) -> Resource:
        """Return the open resource; a MeterError (an I/O error to poll) if none is open."""
        if self.resource is None:
            raise MeterError('no resource is open')
        return self.resource

    def configure(self) -> None:
        """Send the set-up commands, read the unit, then drain the device's error queue."""
        c = self.config
        for name in ('clear_status', 'set_unit', 'set_wavelength', 'set_averaging',
                     'configure'):
            if getattr(c.commands, name):
                self._device().write(c.command(name))
        self.device_unit = self._query_unit() if c.commands.unit_query else UNITS[c.unit]
        self.device_errors = self._drain_errors()
        if self.device_errors:
            self.last_error = 'device reported: ' + '; '.join(self.device_errors)

    def reconfigure(self, config: MeterConfig) -> str:
        """Take a new config; reconnect if what the device is told changed."""
        old, self.config = self.config, config
        keep = ('max_power', 'max_timeouts', 'reconnect_initial', 'reconnect_max',
                'unit_check_every')
        if replace(old, **{k: getattr(config, k) for k in keep}) == config:
            return 'applied'
        self.restart('reconfigured')
        return 'the meter is reconfigured at the next poll'

    def restart(self, why: str) -> None:
        """Close the connection (if any) and reconnect at the next poll, without backoff."""
        self._close_resource()
        self.failures, self.next_attempt, self.last_error = 0, self.monotonic(), why

    def read(self) -> Optional[Reading]:
        """Take one reading (the unit first, when due); None if it is not published."""
        c = self.config
        self.reads += 1
        try:
            if c.commands.unit_query and c.unit_check_every and \
                    self.reads % c.unit_check_every == 0:
                self.device_unit = self._query_unit()
            t0, m0 = self.clock(), self.monotonic()
            reply = self._device().query(c.command('read'))
            t1, m1 = self.clock(), self.monotonic()
        except pyvisa.errors.VisaIOError as exc:
            if exc.error_code != StatusCode.error_timeout:
                self._lost(exc)
                return None
            self._timeout()
            return None
        except IO_ERRORS as exc:
            self._lost(exc)
            return None
        self.consecutive_timeouts = 0
        self.latency_ns.append(int((m1 - m0) * NS))
        power, reason, unit = to_milliwatts(reply, self.device_unit, c.max_power)
        if power is not None and t0 <= 0:
            power, reason = None, 'no_clock'
        if power is None:
            self.skipped[reason] += 1
            self.last_error = f'reading {reply.strip()[:40]!r} ({unit or "unknown unit"}) ' \
                              f'skipped: {reason}'
            return None
        if unit != UNITS[c.unit]:
            self.unit_converted += 1
        self.published += 1
        # the midpoint of the query: see the module docstring
        return Reading(t0 + (t1 - t0) // 2, power, t1 - t0)

    def _query_unit(self) -> Optional[str]:
        return parse_unit(self._device().query(self.config.command('unit_query')))

    def _drain_errors(self) -> list[str]:
        errors = []
        if self.config.commands.error_query:
            for _ in range(MAX_ERRORS_READ):
                reply = self._device().query(self.config.command('error_query')).strip()
                if not reply or reply.split(',')[0].strip() in (NO_ERROR, '+0'):
                    break
                errors.append(reply)
        return errors

    def _timeout(self) -> None:
        self.skipped['timeout'] += 1
        self.consecutive_timeouts += 1
        self.last_error = f'read timed out ({self.consecutive_timeouts} in a row)'
        if self.consecutive_timeouts >= self.config.max_timeouts:
            self.disconnect(f'{self.consecutive_timeouts} timeouts in a row')
            return
        try:        # a reply that arrives late must not be taken for the next one
            self._device().clear()
        except IO_ERRORS:
            pass

    def _lost(self, exc: Exception) -> None:
        self.disconnect(f'I/O error: {describe(exc)}')

    def disconnect(self, why: str) -> None:
        """Close the resource and schedule a reconnection with the backoff."""
        self._drop(f'disconnected ({why})')
        self.disconnects += 1

    def _drop(self, why: str) -> None:
        self._close_resource()
        self.last_error = why
        self.failures += 1
        self.next_attempt = self.monotonic() + self.retry_delay()

    def _close_resource(self) -> None:
        if self.resource is not None:
            try:
                self.resource.close()
            except IO_ERRORS:
                pass
        self.resource = None

    def close(self) -> None:
        """Close the resource and the backend (clean shutdown)."""
        self._close_resource()
        self.opener.close()

    def diagnostics(self) -> tuple[str, str, dict]:
        """
        Return (level, message, values) and start a new rate window.

        ERROR while disconnected; WARN if readings were skipped or converted, or the device
        reported errors, since the previous call; else OK.
        """
        now = self.monotonic()
        t, published, skipped, converted = self._window
        total_skipped = sum(self.skipped.values())
        recent_skips = total_skipped - skipped
        recent_converted = self.unit_converted - converted
        self._window = (now, self.published, total_skipped, self.unit_converted)
        lat = list(self.latency_ns)
        values = {
            'connected': self.connected, 'resource': self.config.resource,
            'identity': self.identity, 'unit': self.config.unit,
            'device_unit': self.device_unit or 'unknown',
            'readings_per_s': (self.published - published) / (now - t) if now > t else 0.0,
            'published': self.published, 'skipped': total_skipped,
            **{f'skipped_{r}': n for r, n in self.skipped.items()},
            'unit_converted': self.unit_converted,
            'latency_last_ms': lat[-1] / 1e6 if lat else 0.0,
            'latency_mean_ms': sum(lat) / len(lat) / 1e6 if lat else 0.0,
            'latency_max_ms': max(lat) / 1e6 if lat else 0.0,
            'connects': self.connects, 'disconnects': self.disconnects,
            'connect_failures': self.connect_failures,
            'retry_in_s': max(self.next_attempt - now, 0.0) if not self.connected else 0.0,
            'device_errors': '; '.join(self.device_errors), 'last_error': self.last_error,
        }
        if not self.connected:
            return 'ERROR', f'not connected: {self.last_error or "connecting"}', values
        if recent_skips or recent_converted or self.device_errors:
            return 'WARN', (f'{recent_skips} reading(s) skipped, {recent_converted} '
                            f'converted from {self.device_unit}; {self.last_error}'), values
        return 'OK', f'reading {self.identity or self.config.resource}', values


def describe(exc: BaseException) -> str:
    """Return an exception as one line: its type and the last line of its message."""
    lines = str(exc).strip().splitlines()
    return f'{type(exc).__name__}: {lines[-1] if lines else ""}'.rstrip(': ')
