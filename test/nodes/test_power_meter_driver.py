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
The power_meter_driver node against the simulated PM100 (pyvisa-sim), faults included.

In-process: each test has its own rclpy Context (the ros_context fixture) and executor;
the faults pyvisa-sim cannot make come from test/visa_faults.py's FaultyOpener.  Every
wait is a condition with a deadline (a bound on DDS and the poll timer, never a timing
assertion).  Expected powers are the simulated meter's reply in W times 1000 (mW, the
unit of received_power), written out.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Illuminance
from std_srvs.srv import Trigger

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import DEFAULT_MEASUREMENT_TYPE, extractor, \
    POWER_TOPIC
from tskf_ros.messages.parameters import flat_parameters
from tskf_ros.messages.power_meter_interface import default_parameters, parameter_names
from tskf_ros.messages.qos import sensor_input_qos, SENSOR_OUTPUT_QOS
from tskf_ros.nodes.power_meter_driver import PowerMeterDriver
from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator
from tskf_ros.tools.demo_collector import wait_for
from visa_faults import bench, FaultyOpener, SIM_YAML
import yaml

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 60.0


class Loop:
    """An executor with a listener node that records received_power and /diagnostics."""

    def __init__(self, context) -> None:
        self.context = context
        self.executor = SingleThreadedExecutor(context=context)
        self.listener = rclpy.create_node('listener', context=context)
        self.power, self.diagnostics = [], []
        self.listener.create_subscription(Illuminance, POWER_TOPIC, self.power.append,
                                          sensor_input_qos(1000))
        self.listener.create_subscription(DiagnosticArray, '/diagnostics',
                                          self._on_diagnostics, 100)
        self.executor.add_node(self.listener)
        self.nodes = [self.listener]

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.diagnostics += [s for s in msg.status if s.name == 'power_meter_driver: power meter']

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def driver(self, b, *, opener=None, **params):
        params = {'backend': b.backend, 'rate': 50.0, 'diagnostic_updater.period': 0.05,
                  'reconnect_initial': 0.05, 'reconnect_max': 0.2, **params}
        return self.add(PowerMeterDriver(context=self.context, opener=opener,
                                         parameter_overrides=[Parameter(k, value=v)
                                                              for k, v in params.items()]))

    def until(self, condition, what):
        wait_for(self.executor, condition, what, TIMEOUT)

    def diagnostics_after(self, condition, what):
        """Return the first diagnostics status, from now on, for which condition holds."""
        start = len(self.diagnostics)
        found = []

        def seen():
            found[:] = [s for s in self.diagnostics[start:] if condition(s)]
            return bool(found)
        self.until(seen, what)
        return found[0]

    def close(self):
        self.executor.shutdown()
        for n in self.nodes:
            n.destroy_node()


@pytest.fixture
def loop(ros_context):
    lp = Loop(ros_context)
    yield lp
    lp.close()


def values(status):
    return {kv.key: kv.value for kv in status.values}


def test_the_parameter_file_sets_every_parameter_to_its_default():
    doc = yaml.safe_load((REPO / 'config' / 'power_meter_driver.yaml').read_text())
    assert list(doc) == ['/**/power_meter_driver']
    assert flat_parameters(doc['/**/power_meter_driver']['ros__parameters']) == \
        default_parameters()
    assert set(default_parameters()) == set(parameter_names())


def test_the_default_backend_is_pyvisa_py_and_the_default_resource_is_simulated():
    values = default_parameters()
    assert values['backend'] == '@py'
    assert values['resource'] in yaml.safe_load(SIM_YAML.read_text())['resources']


def test_publishes_the_meter_reading_in_mw_as_the_simulator_does(loop, tmp_path):
    b = bench(tmp_path)
    b.set_power('3.2E-03')
    t_start = loop.listener.get_clock().now().nanoseconds
    driver = loop.driver(b, wavelength=1310.0, averaging=4, frame_id='meter1')
    loop.until(lambda: len(loop.power) >= 5, '5 readings')
    t_end = loop.listener.get_clock().now().nanoseconds
    assert float(b.query('SENS:CORR:WAV?')) == 1310.0 and b.query('SENS:AVER:COUN?') == '4'
    stamps = []
    for msg in loop.power:
        stamp, power, variance = extractor(DEFAULT_MEASUREMENT_TYPE)(msg, 0)
        assert power == pytest.approx(3.2, rel=1e-12) and variance == 0.0
        assert msg.header.frame_id == 'meter1'
        stamps.append(stamp)
    assert stamps == sorted(set(stamps)) and t_start <= stamps[0] and stamps[-1] <= t_end
    # same topic, type and QoS as the simulator's publisher
    sim = loop.add(PowerMeterSimulator(context=loop.context, namespace='/sim'))
    (mine,) = driver.get_publishers_info_by_topic('/' + POWER_TOPIC)
    (theirs,) = sim.get_publishers_info_by_topic('/sim/' + POWER_TOPIC)
    assert mine.topic_type == theirs.topic_type == 'sensor_msgs/msg/Illuminance'
    for attr in ('reliability', 'durability'):           # what the graph carries
        assert getattr(mine.qos_profile, attr) == getattr(theirs.qos_profile, attr) \
            == getattr(SENSOR_OUTPUT_QOS, attr), attr
    assert driver.pub.qos_profile == sim.sensor_pub.qos_profile == SENSOR_OUTPUT_QOS


def test_the_estimator_takes_the_driver_as_it_takes_the_simulator(loop, tmp_path):
    b = bench(tmp_path)
    est = loop.add(TimescaleEstimator(context=loop.context, cli_args=[
        '--ros-args', '-r', f'measurement:={POWER_TOPIC}']))
    loop.driver(b)
    loop.until(lambda: est.session.stats.received >= 5, 'the estimator to receive 5 readings')
    stats = est.session.stats
    assert stats.accepted >= 5 and sum(stats.rejected.values()) == 0, stats


def test_stamps_follow_the_sim_clock(loop, tmp_path):
    b = bench(tmp_path)
    t_sim = 1_700_000_000 * NS + 123
    clock_pub = loop.listener.create_publisher(ClockMsg, '/clock', 10)
    driver = loop.driver(b, use_sim_time=True)
    # before the first /clock the node's clock reads 0: readings are taken, not published
    loop.until(lambda: driver.session.skipped['no_clock'] >= 3, 'readings without a clock')

    def tick():
        clock_pub.publish(ClockMsg(clock=conversions.ns_to_stamp(t_sim)))
        return len(loop.power) >= 3
    loop.until(tick, '3 readings under use_sim_time')
    # the poll timer is steady (the device runs in real time); with the sim clock standing
    # still, the midpoint of the query is that instant
    assert [conversions.stamp_to_ns(m.header.stamp) for m in loop.power] == \
        [t_sim] * len(loop.power)


def test_absent_at_start_error_then_connects_when_it_appears(loop, tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend, present=False)
    driver = loop.driver(b, opener=opener)
    s = loop.diagnostics_after(lambda s: s.level == DiagnosticStatus.ERROR
                               and int(values(s)['connect_failures']) >= 3,
                               'ERROR diagnostics after 3 failed connections')
    assert values(s)['connected'] == 'False' and 'No device found' in s.message
    assert loop.power == [] and driver.session.published == 0
    opener.plug()
    loop.until(lambda: len(loop.power) >= 3, 'readings once the device appears')
    s = loop.diagnostics_after(lambda s: s.level == DiagnosticStatus.OK, 'OK diagnostics')
    assert values(s)['connected'] == 'True' and int(values(s)['connects']) == 1
    assert loop.power[-1].illuminance == pytest.approx(248.04, rel=1e-12)


def test_a_pulled_cable_is_an_error_until_the_meter_is_back(loop, tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    driver = loop.driver(b, opener=opener)
    loop.until(lambda: len(loop.power) >= 3, '3 readings')
    opener.unplug()
    s = loop.diagnostics_after(lambda s: s.level == DiagnosticStatus.ERROR
                               and int(values(s)['connect_failures']) >= 2,
                               'ERROR diagnostics while unplugged')
    assert 'VI_ERROR_CONN_LOST' in values(s)['last_error'] or \
        'No device found' in values(s)['last_error']
    assert int(values(s)['disconnects']) == 1 and opener.resources[0].closed
    b.set_power('7.5E-03')
    opener.plug()
    loop.until(lambda: loop.power[-1].illuminance == pytest.approx(7.5, rel=1e-12),
               'readings of the new value after the cable is back')
    assert driver.session.connects == 2 and driver.session.disconnects == 1


def test_a_timeout_on_one_read_skips_that_reading_only(loop, tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    driver = loop.driver(b, opener=opener)
    loop.until(lambda: len(loop.power) >= 2, '2 readings')
    opener.timeouts = 1
    loop.until(lambda: opener.timeouts == 0, 'the timeout')
    start = len(loop.power)
    loop.until(lambda: len(loop.power) >= start + 2, 'readings after the timeout')
    s = loop.diagnostics_after(lambda s: values(s)['skipped_timeout'] == '1', 'the count')
    assert values(s)['connected'] == 'True' and values(s)['disconnects'] == '0'
    assert driver.session.skipped['timeout'] == 1


def test_over_range_readings_are_not_published_and_warned(loop, tmp_path):
    b = bench(tmp_path)
    driver = loop.driver(b, max_power=500.0)
    loop.until(lambda: len(loop.power) >= 1, 'a reading')
    for text, reason in [('9.9E37', 'overflow'), ('-1.0E-03', 'negative'),
                         ('NAN', 'not_finite'), ('6.0E-01', 'above_max')]:
        b.set_power(text)
        loop.diagnostics_after(lambda s: s.level == DiagnosticStatus.WARN
                               and int(values(s)[f'skipped_{reason}']) >= 2,
                               f'WARN with skipped_{reason}')
    b.set_power('4.0E-01')
    loop.until(lambda: loop.power[-1].illuminance == pytest.approx(400.0, rel=1e-12),
               'the in-range reading')
    assert all(m.illuminance == pytest.approx(248.04, rel=1e-12)
               or m.illuminance == pytest.approx(400.0, rel=1e-12) for m in loop.power)
    assert driver.session.connected and driver.session.disconnects == 0


def test_a_meter_in_dbm_is_converted(loop, tmp_path):
    b = bench(tmp_path)
    driver = loop.driver(b)
    loop.until(lambda: len(loop.power) >= 1, 'a reading')
    b.set_unit('DBM')
    b.set_power('-13.0')
    loop.until(lambda: loop.power[-1].illuminance == pytest.approx(10 ** -1.3, rel=1e-12),
               '-13 dBm as 0.0501 mW')
    s = loop.diagnostics_after(lambda s: s.level == DiagnosticStatus.WARN, 'WARN')
    assert values(s)['device_unit'] == 'DBM' and int(values(s)['unit_converted']) >= 1
    assert driver.session.skipped['wrong_unit'] == 0


def test_parameters_change_live_or_are_refused_with_the_reason(loop, tmp_path):
    b = bench(tmp_path)
    driver = loop.driver(b)
    loop.until(lambda: len(loop.power) >= 1, 'a reading')
    bad = driver.set_parameters([Parameter('unit', value='dBW')])[0]
    assert not bad.successful and 'unit must be one of' in bad.reason
    assert not driver.set_parameters([Parameter('resource', value='USB0::1::2::3::INSTR')])[
        0].successful                                   # read-only: fixed at start
    assert driver.set_parameters([Parameter('wavelength', value=980.0),
                                  Parameter('rate', value=40.0)])[0].successful
    loop.until(lambda: b.query('SENS:CORR:WAV?') == '9.800000E+02',
               'the new wavelength sent to the meter')
    assert driver.poll_timer.timer_period_ns == NS // 40


def test_the_reset_service_reconnects_at_once(loop, tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    driver = loop.driver(b, opener=opener, reconnect_initial=3600.0, reconnect_max=3600.0)
    loop.until(lambda: len(loop.power) >= 1, 'a reading')
    client = loop.listener.create_client(Trigger, '/power_meter_driver/reset')
    loop.until(client.service_is_ready, 'the ~/reset service')
    future = client.call_async(Trigger.Request())
    loop.until(future.done, 'the answer of ~/reset')
    assert future.result().success
    # no backoff (an hour here): the next poll opens the meter again
    loop.until(lambda: driver.session.connects == 2, 'the second connection')
    start = len(loop.power)
    loop.until(lambda: len(loop.power) > start, 'a reading after the reset')
    assert opener.resources[0].closed and len(opener.resources) == 2


def test_destroying_the_node_closes_the_visa_resource(ros_context, tmp_path):
    b = bench(tmp_path)
    opener = FaultyOpener(b.backend)
    driver = PowerMeterDriver(context=ros_context, opener=opener, parameter_overrides=[
        Parameter('backend', value=b.backend), Parameter('rate', value=100.0)])
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(driver)
    try:
        wait_for(executor, lambda: driver.session.connected, 'connected', TIMEOUT)
    finally:
        executor.shutdown()
        driver.destroy_node()
    assert opener.resources[0].closed and opener.closed


def driver_process(*args, log):
    """Start the power_meter_driver executable (as ros2 run finds it) with this ROS env."""
    exe = Path(sys.prefix) / 'lib' / 'tskf_ros' / 'power_meter_driver'
    command = [str(exe)] if exe.is_file() else [sys.executable, '-m',
                                                'tskf_ros.nodes.power_meter_driver']
    return subprocess.Popen(command + list(args), cwd=REPO, env=dict(os.environ), stdout=log,
                            stderr=subprocess.STDOUT, text=True)


@pytest.mark.slow
def test_the_executable_publishes_with_the_sim_backend_and_default_resource(loop, tmp_path):
    with (tmp_path / 'driver.log').open('w+') as log:
        proc = driver_process('--ros-args', '-p', f'backend:={SIM_YAML}@sim',
                              '-p', 'rate:=20.0', log=log)
        try:
            loop.until(lambda: len(loop.power) >= 3 or proc.poll() is not None,
                       'readings from the driver process')
        finally:
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=TIMEOUT)
            log.seek(0)
            out = log.read()
    assert len(loop.power) >= 3, out
    assert [m.illuminance for m in loop.power] == \
        pytest.approx([248.04] * len(loop.power), rel=1e-12)
    assert proc.returncode == 0 and 'connected to Thorlabs,PM100D' in out, out


def test_a_backend_that_cannot_load_exits_1_with_one_line(tmp_path):
    result = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.power_meter_driver',
                             '--ros-args', '-p', f'backend:={tmp_path}/none.yaml@sim'],
                            cwd=REPO, env=dict(os.environ), capture_output=True, text=True,
                            timeout=TIMEOUT)
    assert result.returncode == 1
    assert 'power_meter_driver: cannot start: VISA backend' in result.stderr
    # one short line: not pyvisa-sim's traceback folded into it
    assert len(result.stderr.strip().splitlines()) == 1 and 'Traceback' not in result.stderr
    assert len(result.stderr) < 400, result.stderr


@pytest.mark.parametrize('override, why', [('rate:=0.0', 'out of range'),
                                           ('rate:=1e9', 'out of range'),
                                           ('rate:=fast', "rate must be a number, got 'fast'")])
def test_a_parameter_ros_refuses_at_start_exits_1_with_one_line(override, why):
    result = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.power_meter_driver',
                             '--ros-args', '-p', f'backend:={SIM_YAML}@sim', '-p', override],
                            cwd=REPO, env=dict(os.environ), capture_output=True, text=True,
                            timeout=TIMEOUT)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 1 and len(lines) == 1, result.stderr
    assert lines[0].startswith('power_meter_driver: cannot start: ') and why in lines[0]


def test_help_exits_0_without_ros():
    result = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.power_meter_driver',
                             '--help'], cwd=REPO, capture_output=True, text=True,
                            timeout=TIMEOUT)
    assert result.returncode == 0 and 'pm100_sim.yaml@sim' in result.stdout
