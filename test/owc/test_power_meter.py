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
The power meter without ROS: SCPI against the simulated PM100 (pyvisa-sim), the faults.

Expected values are written out from the SCPI replies (W -> mW is x 1000, dBm -> mW is
10^(dBm / 10)), never computed by the module under test.  Time is a fake clock the test
moves, so retries and stamps are exact numbers and nothing sleeps.
"""

import math

from hypothesis import given, settings, strategies as st
import pytest

from tskf_ros.owc.meter_settings import (MeterConfig, MeterError, ScpiCommands, SKIP_REASONS,
                                         to_milliwatts)
from tskf_ros.owc.power_meter import PowerMeter
from visa_faults import bench, FaultyOpener


class FakeTime:
    """A monotonic clock (s) the test moves, and a stamping clock (ns) that ticks per call."""

    def __init__(self) -> None:
        self.now = 100.0
        self.ticks = []           # stamping-clock values to hand out, in order

    def monotonic(self) -> float:
        return self.now

    def clock(self) -> int:
        return self.ticks.pop(0) if self.ticks else int(self.now * 1e9)


def meter(b, *, opener=None, time=None, **settings_):
    """Return a PowerMeter on the bench's simulated PM100 (fault-injecting if opener)."""
    time = time or FakeTime()
    return PowerMeter(MeterConfig(backend=b.backend, **settings_), opener=opener,
                      clock=time.clock, monotonic=time.monotonic)


@pytest.mark.parametrize('reply, unit, expected', [
    ('2.480400E-01', 'W', 248.04),
    ('248.04', 'MW', 248.04),
    ('3.5E+02', 'UW', 0.35),
    ('-3.0', 'DBM', 0.501187233627272),          # 10^-0.3
    ('20', 'DBM', 100.0),
    ('1.5E-3 W', 'DBM', 1.5),                    # the reply's own unit wins
    ('-10 dBm', 'W', 0.1),
    ('0', 'W', 0.0),
])
def test_replies_convert_to_milliwatts(reply, unit, expected):
    power, reason, _ = to_milliwatts(reply, unit, 1e4)
    assert reason == '' and power == pytest.approx(expected, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize('reply, unit, reason', [
    ('9.9E37', 'W', 'overflow'), ('+9.90000E+37', 'DBM', 'overflow'),
    ('-9.9E37', 'W', 'overflow'), ('9.91E37', 'W', 'overflow'),
    ('NAN', 'W', 'not_finite'), ('inf', 'W', 'not_finite'), ('-inf', 'DBM', 'not_finite'),
    ('-1.0E-03', 'W', 'negative'), ('-5e-12', 'MW', 'negative'),
    ('10.0001', 'W', 'above_max'), ('40.1', 'DBM', 'above_max'),
    ('', 'W', 'unparseable'), ('OVER', 'W', 'unparseable'), ('1 W 2', 'W', 'unparseable'),
    ('0x1p-3', 'W', 'unparseable'), ('1_0', 'W', 'unparseable'), ('1_0 W', 'W', 'unparseable'),
    ('\u0661\u0660', 'W', 'unparseable'), ('1e', 'W', 'unparseable'), ('.', 'W', 'unparseable'),
    ('1.5.', 'W', 'unparseable'), ('nan1', 'W', 'unparseable'),
    ('1.0', None, 'wrong_unit'), ('1.0 A', 'W', 'wrong_unit'), ('1.0 MA', 'W', 'wrong_unit'),
])
def test_replies_that_are_not_a_power_are_refused_with_the_reason(reply, unit, reason):
    # max_power 1e4 mW = 10 W = 40 dBm
    assert to_milliwatts(reply, unit, 1e4)[:2] == (None, reason)
    assert reason in SKIP_REASONS


@settings(max_examples=300, deadline=None, derandomize=True)
@given(reply=st.one_of(st.text(max_size=30),
                       st.floats(allow_nan=True, allow_infinity=True).map(repr),
                       st.tuples(st.floats(), st.sampled_from(['W', 'dbm', 'mw', 'x']))
                       .map(lambda t: f'{t[0]!r} {t[1]}')),
       unit=st.sampled_from(['W', 'MW', 'UW', 'NW', 'DBM', None]),
       max_power=st.floats(1e-9, 1e12))
def test_whatever_the_meter_says_a_published_power_is_finite_and_in_range(
        reply, unit, max_power):
    power, reason, _ = to_milliwatts(reply, unit, max_power)
    if power is None:
        assert reason in SKIP_REASONS
    else:
        assert reason == '' and math.isfinite(power) and 0.0 <= power <= max_power * (1 + 1e-12)


@pytest.mark.parametrize('change, message', [
    ({'resource': 'not a resource'}, 'not a VISA resource name'),
    ({'unit': 'dBW'}, 'unit must be one of'),
    ({'averaging': 0}, 'averaging=0'),
    ({'reconnect_initial': 5.0, 'reconnect_max': 1.0}, 'reconnect_max'),
    ({'commands': ScpiCommands(set_wavelength='SENS:CORR:WAV {lambda}')}, 'set_wavelength'),
    ({'commands': ScpiCommands(read='')}, 'read command is empty'),
])
def test_a_config_that_cannot_work_is_refused_with_the_reason(change, message):
    with pytest.raises(MeterError, match=message):
        MeterConfig(**change)


def test_a_backend_that_cannot_load_is_refused_with_a_one_line_reason(tmp_path):
    with pytest.raises(MeterError, match='cannot be loaded') as info:
        PowerMeter(MeterConfig(backend=f'{tmp_path}/missing.yaml@sim'))
    assert '\n' not in str(info.value)


def test_connects_configures_and_reads_the_simulated_pm100(tmp_path):
    b = bench(tmp_path)
    m = meter(b, wavelength=1310.0, averaging=10)
    assert m.poll() is None and m.connected          # the first poll connects
    assert m.identity == 'Thorlabs,PM100D,P0000000,2.4.0'
    assert float(b.query('SENS:CORR:WAV?')) == 1310.0
    assert b.query('SENS:AVER:COUN?') == '10' and b.query('SENS:POW:UNIT?') == 'W'
    for text, mw in [('2.480400E-01', 248.04), ('3.2E-03', 3.2), ('1.0E-09', 1e-6)]:
        b.set_power(text)
        reading = m.poll()
        assert reading.power_mw == pytest.approx(mw, rel=1e-12)
    assert m.published == 3 and sum(m.skipped.values()) == 0
    assert m.diagnostics()[0] == 'OK'


# pyvisa-sim warns that its empty answer lacks the termination characters: that answer
# is the point of the test
@pytest.mark.filterwarnings("ignore:read string doesn't end with termination characters")
def test_a_resource_that_does_not_identify_itself_is_not_connected(tmp_path):
    # pyvisa-sim opens any resource name and answers '' to everything: not a meter
    m = meter(bench(tmp_path), resource='USB0::0x1::0x2::NOPE::INSTR')
    assert m.poll() is None and not m.connected
    assert m.connect_failures == 1 and 'no answer to *IDN?' in m.last_error
    assert m.diagnostics()[0] == 'ERROR' and m.published == 0


def test_the_stamp_is_the_midpoint_of_the_query():
    class Instant:
        def query(self, message):
            return '1.0E-03'

        write = clear = close = lambda self, *a: None

    class Opener:
        def open_resource(self, resource, timeout_ms):
            return Instant()

        def close(self):
            pass

    time = FakeTime()
    m = PowerMeter(MeterConfig(commands=ScpiCommands(unit_query='', error_query='')),
                   opener=Opener(), clock=time.clock, monotonic=time.monotonic)
    m.poll()
    # written at 1000 ns, reply back at 5000 ns: stamped at 3000 ns, latency 4000 ns
    time.ticks = [1000, 5000]
    r = m.poll()
    assert (r.stamp_ns, r.latency_ns, r.power_mw) == (3000, 4000, 1.0)
    time.ticks = [7, 8]                      # odd latency: the midpoint rounds down
    assert m.poll().stamp_ns == 7
    time.ticks = [0, 0]                      # a clock not running yet (sim time, no /clock)
    assert m.poll() is None and m.skipped['no_clock'] == 1


def test_over_range_readings_are_skipped_counted_and_warned(tmp_path):
    b = bench(tmp_path)
    m = meter(b, max_power=100.0)            # mW
    m.poll()
    expected = {}
    for text, reason in [('9.9E37', 'overflow'), ('NAN', 'not_finite'),
                         ('-2.0E-06', 'negative'), ('1.01E-01', 'above_max'),
                         ('garbage', 'unparseable')]:
        b.set_power(text)
        assert m.poll() is None
        expected[reason] = expected.get(reason, 0) + 1
        level, message, values = m.diagnostics()
        assert level == 'WARN' and values[f'skipped_{reason}'] == 1, message
    assert {r: n for r, n in m.skipped.items() if n} == expected
    b.set_power('9.9E-02')                  # 99 mW: in range again
    assert m.poll().power_mw == pytest.approx(99.0, rel=1e-12)
    assert m.diagnostics()[0] == 'OK' and m.connected


def test_a_meter_switched_to_dbm_is_converted_an_unknown_unit_refused(tmp_path):
    b = bench(tmp_path)
    m = meter(b)
    m.poll()
    b.set_unit('DBM')                        # someone pressed the front panel's unit key
    b.set_power('-3.0')
    assert m.poll().power_mw == pytest.approx(10 ** -0.3, rel=1e-12)
    assert m.device_unit == 'DBM' and m.unit_converted == 1
    level, message, values = m.diagnostics()
    assert level == 'WARN' and values['unit_converted'] == 1 and 'DBM' in message
    b.set_unit('A')                          # a unit the driver does not know
    b.set_power('1.0E-03')
    assert m.poll() is None and m.skipped['wrong_unit'] == 1
    b.set_unit('W')
    assert m.poll().power_mw == pytest.approx(1.0, rel=1e-12)


def test_a_unit_checked_every_third_reading_is_taken_from_the_last_check(tmp_path):
    b = bench(tmp_path)
    m = meter(b, unit_check_every=3)
    m.poll()
    b.set_unit('DBM')
    b.set_power('10.0')                      # 10 dBm = 10 mW; 10 W = 1e4 mW
    got = [m.poll().power_mw for _ in range(4)]
    # readings 1, 2 trust the unit set at connection (W); reading 3 checks: dBm
    assert got == pytest.approx([1e4, 1e4, 10.0, 10.0], rel=1e-12)


def test_device_errors_at_configuration_are_reported_not_fatal(tmp_path):
    b = bench(tmp_path)
    m = meter(b, wavelength=200.0)           # the simulated sensor covers 400-1800 nm
    m.poll()
    assert m.connected and m.device_errors == ['-100,"Command error"']
    level, message, values = m.diagnostics()
    assert level == 'WARN' and 'Command error' in values['device_errors']
    assert m.poll().power_mw == pytest.approx(248.04, rel=1e-12)


def test_a_real_visa_timeout_skips_the_reading_and_repeated_ones_drop_the_device(tmp_path):
    # SIM:HANG? is never answered: pyvisa-sim's own read timeout, VI_ERROR_TMO
    b = bench(tmp_path)
    m = meter(b, timeout=0.02, max_timeouts=2,
              commands=ScpiCommands(read='SIM:HANG?'))
    m.poll()
    assert m.poll() is None and m.connected and m.skipped['timeout'] == 1
    assert m.poll() is None and not m.connected and m.skipped['timeout'] == 2
    assert m.disconnects == 1 and '2 timeouts in a row' in m.last_error


def test_one_timeout_is_skipped_and_the_next_reading_published(tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    m = meter(b, opener=opener)
    m.poll()
    opener.timeouts = 1
    assert m.poll() is None
    assert m.connected and m.skipped['timeout'] == 1 and opener.resources[0].clears == 1
    assert m.poll().power_mw == pytest.approx(248.04, rel=1e-12)
    assert m.consecutive_timeouts == 0 and m.disconnects == 0


def test_an_absent_device_is_retried_with_capped_exponential_backoff(tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend, present=False)
    time = FakeTime()
    m = meter(b, opener=opener, time=time, reconnect_initial=0.5, reconnect_max=4.0)
    start, attempts = time.now, []
    for k in range(104):                     # 13 s in steps of 1/8 s (exact in binary)
        time.now = start + k / 8
        before = opener.attempts
        m.poll()
        if opener.attempts > before:
            attempts.append(time.now - start)
    # delays 0.5, 1, 2, 4, 4, 4 s (0.5 * 2^k capped at 4) after the first attempt at 0
    assert attempts == [0.0, 0.5, 1.5, 3.5, 7.5, 11.5]
    level, message, values = m.diagnostics()
    assert level == 'ERROR' and 'No device found' in message
    assert values['connect_failures'] == 6 and values['connected'] is False
    opener.plug()
    time.now += 4.0
    assert m.poll() is None and m.connected
    assert m.poll().power_mw == pytest.approx(248.04, rel=1e-12)


def test_a_pulled_cable_disconnects_and_the_meter_comes_back(tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    time = FakeTime()
    m = meter(b, opener=opener, time=time, reconnect_initial=0.5, reconnect_max=2.0)
    m.poll()
    assert m.poll() is not None
    opener.unplug()
    assert m.poll() is None and not m.connected
    assert opener.resources[0].closed and m.disconnects == 1
    assert 'VI_ERROR_CONN_LOST' in m.last_error
    for _ in range(50):                      # 5 s unplugged: retries fail, nothing raises
        time.now += 0.1
        assert m.poll() is None
    assert m.diagnostics()[0] == 'ERROR' and m.connect_failures >= 3
    opener.plug()
    b.set_power('5.0E-03')
    time.now += 2.0                          # the retry delay is capped at 2 s
    assert m.poll() is None and m.connected
    assert m.poll().power_mw == pytest.approx(5.0, rel=1e-12)
    assert m.connects == 2 and m.diagnostics()[0] == 'OK'


def test_close_closes_the_resource_and_the_backend(tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    m = meter(b, opener=opener)
    m.poll()
    m.close()
    assert opener.resources[0].closed and opener.closed and not m.connected
