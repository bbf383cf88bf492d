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

"""
The power meter's settings: command templates, range messages, what counts as a power.

Templates are checked against str.format's own grammar (string.Formatter): a template may
name {unit}, {wavelength} and {averaging} whole, nothing else.  Expected mW are written
out (dBm -> mW is 10^(dBm / 10)).
"""

import math
import sys

from hypothesis import given, settings, strategies as st
import pytest

from tskf_ros.owc.meter_settings import (MeterConfig, MeterError, ScpiCommands, SKIP_REASONS,
                                         to_milliwatts)


@pytest.mark.parametrize('template', [
    '{unit.foo}', '{unit.__class__}', '{wavelength.real}', '{0[1]}', '{unit[0]}', '{}',
    '{0}', '{averaging[x]}', '{wavelength:{unit}}', '{wavelength:>100000000}',
    '{wavelength:.99999f}', 'MEAS:POW? {', 'MEAS:POW? }', '{lambda}',
])
def test_a_template_with_a_field_other_than_the_documented_ones_is_refused(template):
    for name in ('read', 'set_unit', 'identify'):
        with pytest.raises(MeterError, match=f'command scpi_{name} ') as info:
            MeterConfig(commands=ScpiCommands(**{name: template}))
        assert '{unit}, {wavelength}, {averaging}' in str(info.value)
        assert '\n' not in str(info.value)


@pytest.mark.parametrize('template, command', [
    ('SENS:CORR:WAV {wavelength:.3f}', 'SENS:CORR:WAV 1310.000'),
    ('UNIT {unit!s} {{literal}}', 'UNIT DBM {literal}'),
    ('SENS:AVER:COUN {averaging:>5d}', 'SENS:AVER:COUN     7'),
    ('*IDN?', '*IDN?'),
])
def test_a_template_of_the_documented_fields_is_formatted(template, command):
    config = MeterConfig(unit='dBm', wavelength=1310.0, averaging=7,
                         commands=ScpiCommands(read=template))
    assert config.command('read') == command


@settings(max_examples=400, deadline=None, derandomize=True)
@given(template=st.one_of(
    st.text(max_size=30),
    st.lists(st.sampled_from(['{', '}', 'unit', 'wavelength', 'averaging', '.', '[', ']',
                              ':', '!', 'r', 's', 'd', 'g', '0', '9', '>', 'x', ' ']),
             max_size=12).map(''.join)))
def test_any_template_makes_a_config_or_a_meter_error(template):
    try:
        config = MeterConfig(commands=ScpiCommands(read=template or 'MEAS:POW?'))
    except MeterError as exc:
        assert '\n' not in str(exc)
        return
    assert isinstance(config.command('read'), str) and len(config.command('read')) < 10_000


@pytest.mark.parametrize('change, message', [
    ({'averaging': -1}, 'averaging=-1 (must be >= 1)'),
    ({'timeout': 0.0}, 'timeout=0.0 (must be > 0)'),
    ({'reconnect_initial': 5.0, 'reconnect_max': 1.0},
     'reconnect_max=1.0 (must be >= reconnect_initial)'),
])
def test_an_out_of_range_setting_is_named_with_its_own_rule(change, message):
    with pytest.raises(MeterError) as info:
        MeterConfig(**change)
    assert str(info.value) == f'out of range: {message}'


@pytest.mark.parametrize('reply, unit, reason', [
    ('-1e30', 'DBM', 'underflow'),           # 10^-1e29 mW: 0.0 as a double
    ('-3100', 'DBM', 'underflow'),           # 1e-310 mW: subnormal
    ('-1e30 dBm', 'W', 'underflow'),
    ('1e-320', 'NW', 'underflow'),           # 1e-326 mW: 0.0 as a double
    ('2.2e-311', 'W', 'underflow'),          # 2.2e-308 mW: subnormal
    ('-0.0', 'W', 'negative'),               # a negative zero: the meter said negative
    ('-0', 'MW', 'negative'),
    ('-0.0E+00 W', 'DBM', 'negative'),
])
def test_a_reading_that_is_no_positive_power_is_refused_with_the_reason(reply, unit, reason):
    assert to_milliwatts(reply, unit, 1e4)[:2] == (None, reason)
    assert reason in SKIP_REASONS


def test_the_lowest_dbm_that_is_a_normal_double_is_published():
    # 10 log10(2.2250738585072014e-308) = -3076.5... dBm
    power, reason, _ = to_milliwatts('-3076', 'DBM', 1e4)
    assert reason == '' and power == pytest.approx(10 ** -307.6, rel=1e-9)
    assert power >= sys.float_info.min


@settings(max_examples=300, deadline=None, derandomize=True)
@given(value=st.floats(allow_nan=False, allow_infinity=False),
       unit=st.sampled_from(['W', 'MW', 'UW', 'NW', 'DBM']))
def test_a_published_power_is_never_negative_zero_nor_underflowed(value, unit):
    power, reason, _ = to_milliwatts(repr(value), unit, 1e12)
    if power is not None:           # a normal positive double, or the meter's own 0
        assert math.copysign(1.0, power) > 0
        assert power >= sys.float_info.min or (value == 0.0 and unit != 'DBM')
