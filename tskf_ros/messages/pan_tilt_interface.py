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
The alignment node's two-axis mode (axes 2): its parameters and its outcome messages.

One node, one schema (config/schema/alignment.yaml): `axes` chooses the session, and the
parameters shared by both (dt, gain and the controller choice, the supervisor's
pat.enabled, pat.start, pat.hold_samples and pat.lock_*,
max_step, max_backward, state_limit, the input checks, the diagnostics) keep their
one-axis meaning; the pan_tilt.* parameters are the mount's.  x0, P0, Q and R are the
one-axis EKF's 2 x 2 of [x1, x2] (Table I, a pair per sample) and the other pat.* the
one-axis sweep's: the conical-scan EKF (5 states, one sample) and the spiral keep their
own (its R from pan_tilt.noise).  The topics are the
one-axis node's, with two entries in the command ([pan, tilt] in the order of
pan_tilt.joints) and the conical-scan EKF's states in the estimate.
"""

from dataclasses import replace
from typing import Any

from tskf_ros import led
from tskf_ros.led.lock_detector import LockConfig
from tskf_ros.led.pan_tilt_stream import PanTiltStep, PanTiltStreamConfig
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig, CONSISTENT
from tskf_ros.led.two_axis.pan_tilt_session import PanTiltSessionConfig
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig
from tskf_ros.messages.pan_tilt_messages import (check_joints, JOINTS, pan_tilt_command_to_msg,
                                                 pan_tilt_state_to_msg)
from tskf_ros.messages.parameters import NodeConfig

__all__ = ['check_joints', 'JOINTS', 'pan_tilt_config', 'pan_tilt_outcome_messages',
           'supervisor_config']


def method(values: dict) -> str:
    """Return the two-axis aligner the one-axis choices name (ekf only; lqg; the supervisor)."""
    if values['algorithm'] != 'ekf':
        raise led.AlignmentError(f"axes 2 runs the conical-scan EKF: algorithm must be 'ekf', "
                                 f"got {values['algorithm']!r} (the two-axis baselines are "
                                 'in the Monte Carlo experiment, not in the node)')
    if values['controller'] == 'lqg':
        if values['pat.enabled']:
            raise led.AlignmentError('pat.enabled needs controller p: the two-axis supervisor '
                                     'steers the P law; with controller lqg set pat.enabled '
                                     'false')
        return 'conical_lqg'
    return 'conical_ekf_pat' if values['pat.enabled'] else 'conical_ekf'


def filter_config(name: str) -> ConicalEKFConfig:
    """
    Return the conical-scan EKF that pan_tilt.filter names (the noise is pan_tilt.noise).

    first_order: the closed loop's tuned filter (ConicalEKFConfig()); consistent: the one
    whose NEES is in its band at every noise level (conical_ekf.CONSISTENT).
    """
    return CONSISTENT if name == 'consistent' else ConicalEKFConfig()


def supervisor_config(values: dict) -> PanTiltSupervisorConfig:
    """
    Return the two-axis supervisor's settings from the shared pat.* parameters.

    The ones with the same meaning (and default) in both modes: the lock tests
    (lock_detector, unchanged) and the hold.  The sweep's (scan_*), the CUSUM's
    reference, threshold and window, fade, clip_prior and reacquire are the one-axis
    supervisor's: the spiral, its detector (k_ref 0.8 V, spot_detector) and the fade hold
    keep their own.
    """
    base = PanTiltSupervisorConfig()
    lock = LockConfig(window=values['pat.lock_window'],
                      low_count=values['pat.lock_low_count'], level=values['pat.lock_level'],
                      nis_alpha=values['pat.lock_nis_alpha'],
                      corroborate=values['pat.lock_corroborate'])
    return replace(base, lock=lock, hold_samples=values['pat.hold_samples'])


def pan_tilt_config(values: dict) -> NodeConfig:
    """Build the two-axis node config from checked parameter values; AlignmentError if bad."""
    start = values['pat.start'] if values['pat.enabled'] else 'tracking'
    session = PanTiltSessionConfig(
        method=method(values), start=start, dt=values['dt'], noise=values['pan_tilt.noise'],
        joints0=tuple(values['pan_tilt.initial']), max_step=values['max_step'],
        tilt_limits=tuple(values['pan_tilt.tilt_limits']),
        max_backward=values['max_backward'], state_limit=values['state_limit'],
        ekf=replace(filter_config(values['pan_tilt.filter']), gain=values['gain'],
                    radius=values['pan_tilt.scan_radius'],
                    dim_radius=values['pan_tilt.dim_radius'],
                    dim_peak=values['pan_tilt.dim_peak'],
                    wide=values['pan_tilt.wide_prior'],
                    smooth_after=values['pan_tilt.smooth_after'],
                    smooth_every=values['pan_tilt.smooth_every']),
        supervisor=supervisor_config(values))
    session.make_aligner()      # a method the core does not provide yet fails here, at once
    stream = PanTiltStreamConfig(session, values['algorithm'], values['negative_is_missing'],
                                 tuple(values['intensity_range']), values['max_gap'],
                                 values['expected_rate'], values['rate_tolerance'])
    return NodeConfig(stream, values['frame_id'], values['diagnostic_updater.period'],
                      values['queue_depth'], values['status_period'])


def pan_tilt_outcome_messages(step: PanTiltStep, joints: tuple[str, str]) -> list[Any]:
    """Return the (output, message) pairs to publish for a two-axis outcome, in order."""
    out = step.outcome
    if out.command is None:
        return []
    msgs: list[Any] = []
    if out.estimate is not None:
        e = out.estimate
        if step.prior is not None:
            x, P = step.prior
            msgs.append(('predicted', pan_tilt_state_to_msg('predicted', out.stamp_ns,
                                                            step.mu, x, P, e.states)))
        msgs.append(('corrected', pan_tilt_state_to_msg('corrected', out.stamp_ns, step.mu,
                                                        e.x, e.P, e.states)))
    msgs.append(('command', pan_tilt_command_to_msg(out.command, joints)))
    return msgs
