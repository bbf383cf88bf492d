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

"""A real optical power meter (Thorlabs PM100 or any SCPI meter) over VISA: poll and stamp."""

from collections import deque
from dataclasses import replace
from pathlib import Path
import time
from typing import Callable, Optional, Protocol

import pyvisa
from pyvisa.constants import StatusCode
from pyvisa.resources import MessageBasedResource

from tskf_ros.core.units import NS
from tskf_ros.owc.meter_settings import (MAX_ERRORS_READ, MeterConfig, MeterError, NO_ERROR,
                                         parse_unit, Reading, SKIP_REASONS, to_milliwatts,
                                         UNITS)
import yaml

__all__ = ['Opener', 'PowerMeter', 'Resource', 'VisaOpener']


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
        except Exception as exc:  # noqa: B902 - pyvisa-sim raises anything for a bad file
            # (yaml's errors, KeyError, AttributeError, TypeError, Exception itself)
            cause = yaml_problem(backend) or last_line(exc)
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


def yaml_problem(backend: str) -> str:
    """Return why the file of a 'path@sim' backend is not YAML, in one line ('' if it is)."""
    path, _, kind = backend.rpartition('@')
    if kind != 'sim' or not path:
        return ''
    try:
        yaml.safe_load(Path(path).read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f', line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        return f'{path}{where} is not YAML: {getattr(exc, "problem", None) or exc}'
    except (OSError, ValueError):
        return ''           # pyvisa-sim says why it cannot read it
    return ''


def last_line(exc: BaseException) -> str:
    """Return the last line of a message into which pyvisa-sim folded a traceback."""
    text = str(exc)
    for _ in range(3):      # its newlines and quotes come escaped, sometimes twice
        text = text.replace('\\\\', '\\').replace('\\n', '\n').replace("\\'", "'")
    lines = [line.strip().rstrip('\\').strip() for line in text.splitlines()
             if line.strip(' \'"\\')]
    return lines[-1][:200] if lines else type(exc).__name__


def describe(exc: BaseException) -> str:
    """Return an exception as one line: its type and the last line of its message."""
    lines = str(exc).strip().splitlines()
    return f'{type(exc).__name__}: {lines[-1] if lines else ""}'.rstrip(': ')
