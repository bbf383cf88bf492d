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

"""The alignment node's two-axis parameters: which core aligner the shared choices name."""

from dataclasses import replace
import math

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.core.units import NS
from tskf_ros.led.pan_tilt_stream import PanTiltStream, PanTiltStreamConfig
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig, CONSISTENT
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_session import pan_tilt_closed_loop, PanTiltSession
from tskf_ros.led.two_axis.pan_tilt_supervisor_config import PanTiltSupervisorConfig
from tskf_ros.led.two_axis.pointing_geometry import closed_scan_turn
from tskf_ros.messages.alignment_interface import default_parameters, parameters_to_config
from tskf_ros.messages.pan_tilt_interface import pan_tilt_outcome_messages


def two_axis(**extra):
    """Return the node config of the defaults with axes 2 and extra."""
    return parameters_to_config({**default_parameters(), 'axes': 2, **extra})


@pytest.mark.parametrize('extra, method, start', [
    ({'pat.enabled': False}, 'conical_ekf', 'tracking'),
    ({'pat.enabled': True}, 'conical_ekf_pat', 'acquiring'),
    ({'pat.enabled': True, 'pat.start': 'tracking'}, 'conical_ekf_pat', 'tracking'),
    ({'pat.enabled': False, 'controller': 'lqg'}, 'conical_lqg', 'tracking'),
])
def test_the_shared_choices_name_the_two_axis_aligner(extra, method, start):
    config = two_axis(**extra)
    assert isinstance(config.session, PanTiltStreamConfig)
    assert (config.session.session.method, config.session.session.start) == (method, start)


def test_the_shared_limits_reach_the_session():
    s = two_axis(**{'max_step': 10.0, 'max_backward': 2.0, 'state_limit': 50.0, 'dt': 0.1,
                    'pan_tilt.initial': [15.0, -30.0], 'pan_tilt.tilt_limits': [-40.0, 40.0],
                    'pan_tilt.noise': 0.7}).session.session
    assert (s.max_step, s.max_backward, s.state_limit, s.dt, s.noise) == (10.0, 2.0, 50.0,
                                                                          0.1, 0.7)
    assert s.joints0 == (15.0, -30.0) and s.tilt_limits == (-40.0, 40.0)


@pytest.mark.parametrize('extra, why', [
    ({'algorithm': 'three_point'}, "algorithm must be 'ekf'"),
    ({'controller': 'lqg', 'pat.enabled': True}, 'pat.enabled needs controller p'),
    ({'pan_tilt.joints': ['pan', '']}, 'pan_tilt.joints must be two non-empty joint names'),
    ({'axes': 3}, 'axes must be one of 1, 2, got 3'),
    ({'intensity_range': [1.0]},
     'intensity_range must be [lo, hi] with finite lo < hi (or empty), got [1.0]'),
    ({'intensity_range': [5.0, 1.0]}, 'intensity_range must be [lo, hi]'),
    ({'state_limit': 5.0}, 'P0 + Q (one step) has sqrt(trace) 7.35 beyond state_limit 5'),
    ({'intensity_range': [math.nan, 1.0]}, 'intensity_range must be [lo, hi]'),
    ({'pan_tilt.filter': 'unscented'},
     "pan_tilt.filter must be one of first_order, consistent, got 'unscented'"),
])
def test_a_config_that_cannot_run_is_one_line(extra, why):
    with pytest.raises(led.AlignmentError) as info:
        two_axis(**extra)
    assert why in str(info.value) and '\n' not in str(info.value)


def test_the_outcome_messages_are_predicted_corrected_command_in_order():
    stream = PanTiltStream(two_axis(**{'pat.enabled': False}).session)
    first = pan_tilt_outcome_messages(stream.add(NS, 2.5), ('pan', 'tilt'))
    assert [key for key, _ in first] == ['predicted', 'corrected', 'command']
    rejected = stream.add(NS, 2.5)                    # the same stamp: dropped
    assert rejected.outcome.status == 'rejected'
    assert pan_tilt_outcome_messages(rejected, ('pan', 'tilt')) == []


def test_at_the_defaults_the_two_axis_filter_and_supervisor_are_the_core_defaults():
    s = two_axis().session.session
    assert s.ekf == ConicalEKFConfig() and s.supervisor == PanTiltSupervisorConfig()


@pytest.mark.parametrize('pat', [False, True])
def test_pan_tilt_filter_consistent_is_the_consistent_filter_with_the_node_noise(pat):
    """
    pan_tilt.filter: consistent runs CONSISTENT, with pan_tilt.noise and gain as given.

    pan_tilt.smooth_after and smooth_every apply to it as to first_order (100 and 50 by default).
    """
    s = two_axis(**{'pan_tilt.filter': 'consistent', 'pan_tilt.noise': 0.7, 'gain': 0.4,
                    'pat.enabled': pat}).session.session
    assert s.ekf == replace(CONSISTENT, gain=0.4, smooth_after=100)
    tracker = PanTiltSession(s).tracker
    assert tracker.config == replace(CONSISTENT, gain=0.4, noise=0.7, smooth_after=100)
    np.testing.assert_allclose(tracker.R[0, 0, 0], 0.7 ** 2 + CONSISTENT.model_noise ** 2,
                               rtol=1e-12)


def test_gain_and_the_shared_pat_parameters_reach_the_two_axis_configs():
    s = two_axis(**{'gain': 1.2, 'pat.hold_samples': 7, 'pat.detector_reference': 0.8,
                    'pat.lock_window': 30, 'pat.lock_low_count': 20, 'pat.lock_level': 0.4,
                    'pat.lock_nis_alpha': 1e-3, 'pat.lock_corroborate': 5}).session.session
    assert s.ekf.gain == 1.2 and s.supervisor.hold_samples == 7
    # the spiral's CUSUM keeps its own k_ref (the one-axis sweep's is pat.detector_reference)
    assert s.supervisor.detector == PanTiltSupervisorConfig().detector
    lock = s.supervisor.lock
    assert (lock.window, lock.low_count, lock.level, lock.nis_alpha, lock.corroborate) == (
        30, 20, 0.4, 1e-3, 5)
    aligner = PanTiltSession(s).aligner
    assert aligner.tracker.config.gain == 1.2 and aligner.config.lock == lock


def test_the_scan_circle_parameters_reach_the_filter_and_its_radius():
    """pan_tilt.scan_radius, dim_radius and dim_peak: the EKF's circle, per run as it dims."""
    s = two_axis(**{'pat.enabled': False, 'pan_tilt.scan_radius': 3.0,
                    'pan_tilt.dim_radius': 8.0, 'pan_tilt.dim_peak': 2.5}).session.session
    assert (s.ekf.radius, s.ekf.dim_radius, s.ekf.dim_peak) == (3.0, 8.0, 2.5)
    tracker = PanTiltSession(s).tracker
    np.testing.assert_allclose(np.hypot(*np.reshape(tracker.scan_offset, (-1, 2)).T), 3.0,
                               rtol=1e-12)
    fixed = two_axis(**{'pan_tilt.dim_radius': 0.0}).session.session.ekf
    assert fixed == replace(ConicalEKFConfig(), dim_radius=0.0)


def test_the_wide_prior_reaches_the_filter():
    """pan_tilt.wide_prior: 0 (off) by default; a width turns the regression on per run."""
    assert two_axis().session.session.ekf == ConicalEKFConfig()
    ekf = two_axis(**{'pan_tilt.wide_prior': 2.5}).session.session.ekf
    assert ekf == replace(ConicalEKFConfig(), wide=2.5)
    assert PanTiltSession(two_axis(**{'pan_tilt.wide_prior': 2.5}).session.session
                          ).tracker.config.wide == 2.5


def test_the_smoother_reaches_the_filter():
    """pan_tilt.smooth_after: 100 samples by default, 0 turns the smoother off."""
    assert two_axis().session.session.ekf.smooth_after == 100
    off = two_axis(**{'pan_tilt.smooth_after': 0}).session.session
    assert off.ekf == replace(ConicalEKFConfig(), smooth_after=0)
    assert PanTiltSession(off).tracker.window is None


def test_the_smoothing_again_reaches_the_filter():
    """pan_tilt.smooth_every: 50 samples by default, 0 smooths once only."""
    assert two_axis().session.session.ekf.smooth_every == 50
    once = two_axis(**{'pan_tilt.smooth_every': 0}).session.session
    assert once.ekf == replace(ConicalEKFConfig(), smooth_every=0)


@pytest.mark.parametrize('gain', [0.25, 0.5, 1.5])
def test_gain_is_the_p_law_of_eq_21_in_two_axes(gain):
    """The first turn is -G dhat and the scan's step (d has no drift yet: b stays 0)."""
    session = PanTiltSession(two_axis(**{'pat.enabled': False, 'gain': gain}).session.session)
    s0 = session.tracker.scan_offset.copy()
    out = session.add(NS, 0.5)
    s1 = session.tracker.scan_offset
    d = np.array(out.estimate.error)
    assert np.all(out.estimate.x[3:5] == 0.0) and np.linalg.norm(d) > 1e-4
    tilt = default_parameters()['pan_tilt.initial'][1]
    # (the offsets are per run, (1, 2), with the circle that widens when dim)
    expected = closed_scan_turn(-gain * d, s0, s1, tilt)
    np.testing.assert_allclose(out.turn, np.reshape(expected, 2), rtol=0,
                               atol=1e-12)


@pytest.mark.parametrize('hold, steering', [(0, False), (200, True)])
def test_pat_hold_samples_holds_a_blocked_light_in_two_axes_as_in_one(hold, steering):
    """Blocked from 4 s: with pat.hold_samples 0 the supervisor searches, with 200 it holds."""
    session = PanTiltSession(two_axis(**{'pat.start': 'tracking', 'pat.hold_samples': hold,
                                         'pan_tilt.noise': 0.5}).session.session)
    link = PanTiltLinkConfig(noise=0.5, blocked=(4.0, 20.0))
    loop = pan_tilt_closed_loop(link, session, 160, seed=3)
    assert loop.outcomes[-1].state == 'lost'
    assert session.steering is steering
