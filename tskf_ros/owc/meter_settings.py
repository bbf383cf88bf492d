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

"""The settings of an SCPI optical power meter and the reading of its replies in mW."""

from dataclasses import dataclass, field, fields
import math
import re
import string
import sys
from typing import Optional

# the simulated PM100D of config/pm100_sim.yaml; a real one: USB0::0x1313::0x8078::<serial>
DEFAULT_RESOURCE = 'USB0::0x1313::0x8078::P0000000::INSTR'
# SCPI unit word -> mW per unit ('MW' is milliwatt: SCPI suffixes are case-blind, M = milli)
LINEAR_UNITS = {'W': 1e3, 'MW': 1.0, 'UW': 1e-3, 'NW': 1e-6}
DBM = 'DBM'
UNITS = {'W': 'W', 'mW': 'MW', 'dBm': DBM}      # the unit parameter -> its SCPI word
# SCPI's overflow (+-9.9E37) and not-a-number (9.91E37) sentinels
SCPI_OVERFLOW = 9.9e37
# a reply's number: SCPI's decimal numeric data (NR1, NR2, NR3: 12, 1.5, -2.480400E-01),
# and the words NAN and INF some meters send (refused later as not finite); Python's float
# takes more (1_0, 0x1p-3 as float.fromhex, Unicode digits), which no meter means
SCPI_NUMBER = re.compile(r'[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?'
                         r'|[+-]?(?:nan|inf|infinity)', re.ASCII | re.IGNORECASE)
# why a reading was not published; 'no_clock': the stamping clock read 0 (a node on
# use_sim_time before /clock arrives), a stamp the estimator would reject
# 'negative' includes -0.0 in W (a sign the meter gave); 'underflow': a positive reading so
# small (-1e30 dBm, 1e-320 nW) that its mW is not a normal double (0.0 or subnormal)
SKIP_REASONS = ('timeout', 'overflow', 'not_finite', 'negative', 'underflow', 'above_max',
                'unparseable', 'wrong_unit', 'no_clock')
# the fields a command template may name, whole ('{unit}', '{wavelength:g}'): no attribute
# or index ('{unit.foo}', '{0[1]}'), no positional field
TEMPLATE_FIELDS = ('unit', 'wavelength', 'averaging')
# the longest width or precision a template's format spec may ask for
MAX_FORMAT_DIGITS = 3
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
            from pyvisa import rname
        except ModuleNotFoundError:     # no extra `visa`: a replay, which opens no meter
            pass
        else:
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
            raise MeterError('out of range: ' + ', '.join(
                f'{n}={getattr(self, n)!r} ({RANGE_TEXT[n]})' for n in bad))
        if not self.commands.read:
            raise MeterError('the read command is empty')
        for f in fields(ScpiCommands):
            self.command(f.name)

    def command(self, name: str) -> str:
        """Return the command `name` with {unit}, {wavelength} and {averaging} filled in."""
        template = getattr(self.commands, name)
        try:
            check_template(template)
            return template.format(unit=UNITS[self.unit], wavelength=self.wavelength,
                                   averaging=self.averaging)
        except (ValueError, TypeError, LookupError, AttributeError) as exc:
            raise MeterError(f'command scpi_{name} {template!r}: {exc} (fields: {{unit}}, '
                             '{wavelength}, {averaging})') from None


RANGE_TEXT = {'wavelength': 'must be > 0', 'averaging': 'must be >= 1',
              'timeout': 'must be > 0', 'max_power': 'must be > 0',
              'max_timeouts': 'must be >= 1', 'reconnect_initial': 'must be > 0',
              'reconnect_max': 'must be >= reconnect_initial',
              'unit_check_every': 'must be >= 0'}


def check_template(template: str) -> None:
    """Raise ValueError unless every field of template is one of TEMPLATE_FIELDS, whole."""
    for _, field_name, spec, _ in string.Formatter().parse(template):
        if field_name is None:
            continue
        if field_name not in TEMPLATE_FIELDS:
            raise ValueError(f'{{{field_name}}} is not a field (attributes, indexes and '
                             'positions are not allowed)')
        if spec and ('{' in spec or '}' in spec):
            raise ValueError(f'the format spec {spec!r} of {{{field_name}}} has a field')
        if any(len(digits) > MAX_FORMAT_DIGITS for digits in _digit_runs(spec or '')):
            raise ValueError(f'the format spec {spec!r} of {{{field_name}}} asks for more '
                             f'than {MAX_FORMAT_DIGITS} digits of width or precision')


def _digit_runs(text: str) -> list[str]:
    return ''.join(c if c.isdigit() else ' ' for c in text).split()


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
        if not 1 <= len(parts) <= 2 or not SCPI_NUMBER.fullmatch(parts[0]):
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
        # P [mW] = 10^(P [dBm] / 10): a positive power, unless it underflows (-1e30 dBm)
        if value > 10 * math.log10(max_power):
            return None, 'above_max', unit
        mw = 10.0 ** (value / 10.0)
        if mw < sys.float_info.min:
            return None, 'underflow', unit
        return mw, '', unit
    if math.copysign(1.0, value) < 0:           # -0.0 W too: the meter said negative
        return None, 'negative', unit
    mw = value * LINEAR_UNITS[unit]
    if value > 0 and mw < sys.float_info.min:   # 1e-320 nW: not 0.0, not subnormal
        return None, 'underflow', unit
    if mw > max_power:
        return None, 'above_max', unit
    return mw, '', unit
