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
The two-axis alignment loop over DDS (simulator + alignment node, `axes: 2`), and its parameters.

The reference is the ROS-free loop on the same seed: two_axis.pan_tilt_session's
pan_tilt_closed_loop, the steppable PanTiltLink against a PanTiltSession built from the
node's own config.  Over DDS the nodes must give the same off-axis angles, commands and
estimates to 1e-9 (degrees, radians and volts: only the conversions to and from radians and
the messages' floats lie between them, so the difference is rounding, about 1e-14).
"""

import os
from pathlib import Path
import subprocess
import sys

from node_helpers import TIMEOUT
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String

from tskf_ros.core.units import NS
from tskf_ros.led.alignment_session import AlignmentSession
from tskf_ros.led.pan_tilt_stream import PanTiltStream
from tskf_ros.led.two_axis import conical_ekf
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_session import pan_tilt_closed_loop, PanTiltSession
from tskf_ros.led.two_axis.pan_tilt_session import PanTiltSessionConfig
from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import (COMMAND_TOPIC, OUTPUT_TOPICS,
                                                   pat_state_qos, PAT_STATE_TOPIC)
from tskf_ros.messages.pan_tilt_messages import (msg_to_pan_tilt_state, msg_to_pan_tilt_truth,
                                                 STATE_LABELS)
from tskf_ros.messages.parameter_schema import load_schema, ParameterError
from tskf_ros.messages.parameters import flat_parameters
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.led_link_simulator import LedLinkSimulator
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.tools.demo_collector import wait_for

import yaml

REPO = Path(__file__).resolve().parents[2]
LOOP_FILE = REPO / 'config' / 'pan_tilt_loop.yaml'
DT = 0.05
TRACKING = 15.0     # deg: the tracking zone's half-angle
CONVERGED = 40      # samples (2 s) after which the off-axis angle stays in the zone


def loop_parameters(node, **extra):
    """Parameter overrides from config/pan_tilt_loop.yaml's section of node, plus extra."""
    data = yaml.safe_load(LOOP_FILE.read_text())[f'/**/{node}']['ros__parameters']
    values = flat_parameters(data)
    values.update(extra)
    return [Parameter(k, value=v) for k, v in values.items()]


# (simulator overrides, alignment overrides, samples after which the light is tracked):
# the P law from a known prior, with dropouts and noise 1 V, the LQR per axis, the consistent
# filter (pan_tilt.filter), the supervisor's cold search from 20 deg off the boresight, and
# the supervisor on stamps jittered by +-20 ms (pan_tilt.jitter)
@pytest.mark.parametrize('link, aligner, converged', [
    ({'seed': 3, 'blockage': 'none'}, {}, CONVERGED),
    ({'seed': 5, 'blockage': 'bernoulli', 'drop_probability': 0.3, 'noise': 1.0}, {},
     CONVERGED),
    ({'seed': 4}, {'controller': 'lqg'}, CONVERGED),
    ({'seed': 5, 'blockage': 'bernoulli', 'drop_probability': 0.3, 'noise': 1.0},
     {'pan_tilt.filter': 'consistent'}, CONVERGED),
    ({'seed': 3, 'phi0': 20.0}, {'pat.enabled': True}, 100),
    ({'seed': 6, 'noise': 1.0, 'pan_tilt.jitter': 0.02}, {'pat.enabled': True}, CONVERGED),
], ids=['p', 'p_dropouts_noise_1V', 'lqg', 'consistent_filter', 'supervisor_cold_start',
        'supervisor_jittered_stamps'])
def test_two_axis_loop_over_dds_equals_the_ros_free_loop(ros_context, executor_kind, link,
                                                         aligner, converged, monkeypatch):
    steps = 300
    sim = LedLinkSimulator(context=ros_context, parameter_overrides=loop_parameters(
        'led_link_simulator', **link, time_factor=0.0, duration=steps * DT, start_time=1.0,
        wait_for_subscribers=1, command_timeout=TIMEOUT))
    # negative_is_missing false: the reference session takes every reading as it is (with
    # noise 1 V some are negative)
    node = Alignment(context=ros_context, parameter_overrides=loop_parameters(
        'alignment', negative_is_missing=False, **{'pan_tilt.noise': sim.config.link.noise},
        **aligner))
    assert isinstance(node.session, PanTiltStream)
    # the reference: the ROS-free loop, same link, same seed, the node's own session config;
    # the filter's stamps (s from the session's first sample) where its smoother replaced
    # the estimate (at the end of each window, pan_tilt.smooth_after and smooth_every)
    smoothed: list[float] = []

    def smooth_window(filt, record):
        smoothed.append(filt.clock.stamp)
        return window_smoother(filt, record)
    window_smoother = conical_ekf.smooth_window
    monkeypatch.setattr(conical_ekf, 'smooth_window', smooth_window)
    ref = pan_tilt_closed_loop(sim.config.pan_tilt, PanTiltSession(node.config.session.session),
                               steps, seed=sim.config.link.seed)
    monkeypatch.undo()
    origin_ns = next(NS + int(round(s.t * NS)) for s in ref.samples if not bool(s.missing[0]))
    smoothed_ns = np.array([origin_ns + t * NS for t in smoothed])
    assert len(smoothed) >= 2       # 300 samples: at the 100th, then every 50th
    delivered = sum(not bool(s.missing[0]) for s in ref.samples)
    client = rclpy.create_node('client', context=ros_context)
    truth, commands, corrected = [], [], []
    deep = QoSProfile(depth=1000)
    client.create_subscription(JointState, 'true_angle', truth.append, deep)
    client.create_subscription(Float64MultiArray, COMMAND_TOPIC, commands.append, deep)
    client.create_subscription(Float64MultiArray, OUTPUT_TOPICS['corrected'], corrected.append,
                               deep)
    states, predicted = [], []
    client.create_subscription(String, PAT_STATE_TOPIC, states.append, pat_state_qos())
    client.create_subscription(Float64MultiArray, OUTPUT_TOPICS['predicted'], predicted.append,
                               deep)
    estimated = sum(1 for o in ref.outcomes if o is not None and o.estimate is not None)
    # a prediction into every estimated sample but the hand-over's (the supervisor's fit)
    predictions = estimated - (1 if aligner.get('pat.enabled') else 0)
    executor = make_executor(executor_kind, context=ros_context)
    for n in (sim, node, client):
        executor.add_node(n)
    try:
        wait_for(executor, lambda: len(truth) == steps and len(commands) == delivered
                 and len(corrected) == estimated and len(predicted) == predictions,
                 lambda: f'the loop ({len(truth)} truth, {len(commands)} commands of '
                 f'{delivered}, {len(corrected)} estimates of {estimated})', TIMEOUT)
    finally:
        executor.shutdown()
        for n in (sim, node, client):
            n.destroy_node()
    read = [msg_to_pan_tilt_truth(m) for m in truth]
    stamps = [stamp for stamp, _ in read]
    assert stamps == [NS + int(round(s.t * NS)) for s in ref.samples]
    if link.get('pan_tilt.jitter'):     # k dt + U(-jitter, jitter): mu from the stamps
        offsets = np.array(stamps) - NS - np.arange(steps) * int(DT * NS)
        assert 0.015 * NS < np.abs(offsets).max() <= 0.02 * NS
    else:
        assert stamps == [NS + k * int(DT * NS) for k in range(steps)]
    assert list(truth[0].name) == ['pan', 'tilt', 'source_azimuth', 'source_elevation',
                                   'off_axis']
    theta = np.array([angles['off_axis'] for _, angles in read])
    np.testing.assert_allclose(theta, ref.theta(), rtol=0, atol=1e-9)
    joints = np.array([[angles['pan'], angles['tilt']] for _, angles in read])
    np.testing.assert_allclose(joints, [s.joints[0] for s in ref.samples], rtol=0, atol=1e-9)
    outcomes = [o for o in ref.outcomes if o is not None and o.command is not None]
    assert len(outcomes) == delivered
    got = np.array([conversions.msg_to_base_command(m) for m in commands])
    np.testing.assert_allclose(got, [o.command for o in outcomes], rtol=0, atol=1e-9)
    assert all(list(m.layout.dim[0].label.split(',')) == ['pan', 'tilt'] for m in commands)
    # the prediction into each sample the filter steered at before (not the hand-over's)
    before = [msg_to_pan_tilt_state(m) for m in predicted]
    after = {e.stamp_ns: e for e in map(msg_to_pan_tilt_state, corrected)}
    for e in before:
        assert e.kind == 'predicted' and e.mu == after[e.stamp_ns].mu
        if not np.any(np.abs(smoothed_ns - e.stamp_ns) < 1e3):    # an update's, not the smoother's
            assert np.trace(e.P) >= np.trace(after[e.stamp_ns].P)
    for msg, o in zip(corrected, [o for o in outcomes if o.estimate is not None]):
        e = msg_to_pan_tilt_state(msg)
        assert e.kind == 'corrected' and e.stamp_ns == o.stamp_ns
        assert e.names == tuple(STATE_LABELS[s] for s in o.estimate.states)
        np.testing.assert_allclose(e.x, o.estimate.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(e.P, o.estimate.P, rtol=1e-12, atol=1e-9)
    assert sim.timeouts == 0 and sim.bad_commands == 0
    stats = node.session.stats
    assert stats.received == stats.used == stats.commands == delivered
    assert theta[converged:].max() < TRACKING
    if aligner.get('pat.enabled'):
        # searching (no estimate) until the light is found, then tracking, on pat_state
        # (latched, depth 1: a subscriber matched after the hand-over gets only 'tracking')
        got = [m.data for m in states]
        assert got in (['acquiring', 'tracking'], ['tracking']), got
        assert 0 < delivered - estimated < converged
        assert node.session.pointing.acquisitions == 1
    else:
        assert estimated == delivered and [m.data for m in states] in ([], ['disabled'])
    if link.get('blockage', 'bernoulli') != 'none':
        assert delivered < steps and stats.gaps > 0


# -- parameters -----------------------------------------------------------------------------


@pytest.mark.parametrize('node, override, why', [
    (Alignment, Parameter('axes', value=3), 'axes must be one of 1, 2, got 3'),
    (LedLinkSimulator, Parameter('axes', value=0), 'axes must be one of 1, 2, got 0'),
    (Alignment, Parameter('pan_tilt.joints', value=['pan', 'pan']),
     "pan_tilt.joints must have no duplicates, got ['pan', 'pan']"),
    (Alignment, Parameter('pan_tilt.joints', value=['pan']),
     "pan_tilt.joints must have 2 entries, got ['pan']"),
    (Alignment, Parameter('pan_tilt.tilt_limits', value=[-85.0, 80.0]),
     'pan_tilt.tilt_limits must have each entry within [-80, 80], got [-85.0, 80.0]'),
])
def test_a_bad_axes_or_joints_value_is_one_parameter_error(ros_context, node, override, why):
    with pytest.raises(ParameterError) as info:
        node(context=ros_context, parameter_overrides=[override])
    assert str(info.value) == why


@pytest.mark.parametrize('joints', [['pan', ''], [' ', 'tilt']])
@pytest.mark.parametrize('node', [Alignment, LedLinkSimulator])
def test_an_empty_joint_name_is_refused_in_one_line(ros_context, node, joints):
    with pytest.raises(ValueError) as info:
        node(context=ros_context, parameter_overrides=[
            Parameter('axes', value=2), Parameter('pan_tilt.joints', value=joints)])
    assert str(info.value) == (f'pan_tilt.joints must be two non-empty joint names, got '
                               f'{joints}')


@pytest.mark.parametrize('extra, why', [
    ({'algorithm': 'hill_climbing'}, 'axes 2 runs the conical-scan EKF: algorithm must be '
     "'ekf', got 'hill_climbing'"),
    ({'pan_tilt.initial': [0.0, 85.0]}, "the start tilt 85 deg (joints0, the node's "
     'pan_tilt.initial) is outside tilt_limits [-80.0, 80.0]'),
    ({'intensity_range': [1.0]}, 'intensity_range must be [lo, hi] with finite lo < hi (or '
     'empty), got [1.0]'),
    ({'controller': 'lqg', 'pat.enabled': True}, 'pat.enabled needs controller p'),
])
def test_a_two_axis_alignment_config_that_cannot_run_is_refused(ros_context, extra, why):
    with pytest.raises(ValueError) as info:
        Alignment(context=ros_context, parameter_overrides=loop_parameters('alignment',
                                                                           **extra))
    assert why in str(info.value) and '\n' not in str(info.value)


@pytest.mark.parametrize('extra, why', [
    ({'blockage': 'gilbert_elliott'}, 'axes 2 takes blockage none or bernoulli'),
    ({'max_speed': 10.0}, 'max_speed must be 0'),
    ({'phi0': 120.0}, 'phi0'),
    # stamps k dt + U(-jitter, jitter) would reorder from dt/2 on
    ({'pan_tilt.jitter': 0.025}, 'jitter must be in [0, dt/2), got 0.025'),
])
def test_a_two_axis_link_that_cannot_be_simulated_is_refused(ros_context, extra, why):
    with pytest.raises(ValueError) as info:
        LedLinkSimulator(context=ros_context, parameter_overrides=loop_parameters(
            'led_link_simulator', **extra))
    assert why in str(info.value) and '\n' not in str(info.value)


def test_axes_is_read_only_and_a_tilt_limit_change_restarts_the_two_axis_aligner(ros_context):
    node = Alignment(context=ros_context, parameter_overrides=loop_parameters('alignment'))
    try:
        assert not node.set_parameters([Parameter('axes', value=1)])[0].successful
        assert isinstance(node.session, PanTiltStream)
        node._on_intensity(conversions.intensity_to_msg(NS, 2.5))
        result = node.set_parameters([Parameter('pan_tilt.tilt_limits', value=[-30.0, 30.0])])
        assert result[0].successful, result[0].reason
        assert node.session.config.session.tilt_limits == (-30.0, 30.0)
        assert node.session.stats.resets['reconfigured'] == 1
        # the shared filter and supervisor parameters reach the two-axis aligner
        result = node.set_parameters([Parameter('gain', value=1.1),
                                      Parameter('pat.hold_samples', value=30)])
        assert all(r.successful for r in result), [r.reason for r in result]
        session = node.session.config.session
        assert session.ekf.gain == 1.1 and session.supervisor.hold_samples == 30
        # refused with the reason, and the node keeps its config
        result = node.set_parameters([Parameter('algorithm', value='three_point')])[0]
        assert not result.successful and "algorithm must be 'ekf'" in result.reason
        assert node.config.session.algorithm == 'ekf'
    finally:
        node.destroy_node()


def test_one_axis_stays_the_default(ros_context):
    node = Alignment(context=ros_context)
    sim = LedLinkSimulator(context=ros_context)
    try:
        assert isinstance(node.session, AlignmentSession) and sim.config.pan_tilt is None
        assert load_schema('alignment').defaults()['axes'] == 1
    finally:
        node.destroy_node()
        sim.destroy_node()


def test_a_one_entry_command_to_the_two_axis_simulator_is_ignored(ros_context):
    sim = LedLinkSimulator(context=ros_context, parameter_overrides=loop_parameters(
        'led_link_simulator'))
    try:
        sim._on_command(Float64MultiArray(data=[0.1]))
        sim._on_command(Float64MultiArray(data=[0.1, float('nan')]))
        assert sim.bad_commands == 2 and sim.commands == 0
        sim._on_command(Float64MultiArray(data=[0.1, 0.3]))
        assert sim.commands == 1
        np.testing.assert_allclose(sim.link.target[0], np.rad2deg([0.1, 0.3]), rtol=1e-15)
    finally:
        sim.destroy_node()


def test_the_two_axis_defaults_are_the_core_defaults():
    align = load_schema('alignment').defaults()
    session = PanTiltSessionConfig()
    assert align['pan_tilt.initial'] == list(session.joints0)
    assert align['pan_tilt.noise'] == session.noise
    assert tuple(align['pan_tilt.tilt_limits']) == session.tilt_limits
    sim = load_schema('led_link_simulator').defaults()
    assert sim['pan_tilt.elevation0'] == PanTiltLinkConfig().elevation0
    assert sim['pan_tilt.joints'] == align['pan_tilt.joints'] == ['pan', 'tilt']


def test_axes_3_exits_1_with_one_line():
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.nodes.alignment', '--ros-args',
                           '-p', 'axes:=3'], cwd=REPO, env=dict(os.environ),
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 1
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and 'axes must be one of 1, 2, got 3' in lines[0], proc.stderr


def test_the_offline_replay_refuses_a_two_axis_parameter_file_in_one_line(tmp_path, capsys):
    from tskf_ros.bag.replay.cli import main
    out = tmp_path / 'out'
    assert main(['--filter', 'alignment', str(REPO / 'bags' / 'led_pan_tilt'), str(out),
                 '--params-file', str(LOOP_FILE)]) == 1
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [f'replay_offline: error: {LOOP_FILE}: axes 2: the offline tools replay '
                     'one axis; the two-axis loop runs live (pan_tilt_loop.launch.py)']
    assert not out.exists()


def test_acquire_forces_a_search_with_the_two_axis_supervisor_only(ros_context):
    for enabled, want in ((True, True), (False, False)):
        node = Alignment(context=ros_context, parameter_overrides=loop_parameters(
            'alignment', **{'pat.enabled': enabled, 'pat.start': 'tracking'}))
        try:
            assert node.session.pat_state == ('tracking' if enabled else 'disabled')
            assert node.session.acquire() is want
            assert node.session.pat_state == ('acquiring' if enabled else 'disabled')
        finally:
            node.destroy_node()
