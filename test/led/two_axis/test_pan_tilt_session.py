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

"""The two-axis session: stamps in, joint commands out, bad input refused."""

import math

import numpy as np
import pytest

from tskf_ros.led.intensity_model import AlignmentError
from tskf_ros.led.two_axis.aligners import make_two_axis_aligner
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_session import (pan_tilt_closed_loop, PanTiltSession,
                                                    PanTiltSessionConfig)
from tskf_ros.led.two_axis.pan_tilt_simulation import simulate_pan_tilt

NS = 1_000_000_000


def test_closed_loop_matches_the_vectorised_simulation():
    """The session on the one-run link gives the same boresight angles as simulate_pan_tilt."""
    link = PanTiltLinkConfig(steps=200, noise=0.5)
    session = PanTiltSession(PanTiltSessionConfig(method='conical_ekf', max_step=0.0))
    loop = pan_tilt_closed_loop(link, session, link.steps, seed=11)
    traj = simulate_pan_tilt(make_two_axis_aligner('conical_ekf'), link, 11)
    # the session's joints go through pan/tilt and back: equal to rounding
    np.testing.assert_allclose(loop.theta(), traj.theta[:, 0], atol=1e-9)


def test_outcome_carries_commands_estimate_and_state():
    """A used sample: absolute joints, the turn, x1 and both errors with a 3x3 covariance."""
    session = PanTiltSession()
    out = session.add(NS, 2.5)
    assert out.status == 'used' and out.state == 'disabled'
    assert out.command is not None and out.estimate is not None
    assert out.estimate.covariance.shape == (3, 3)
    assert out.estimate.states[:3] == ('x1', 'd_c', 'd_e')
    np.testing.assert_allclose(out.estimate.covariance, out.estimate.covariance.T)


def test_missing_samples_are_predicted_over():
    """None and NaN are missing: the covariance of the errors grows, a command still comes."""
    session = PanTiltSession()
    session.add(NS, 2.5)
    p0 = session.estimate().covariance[1, 1]
    for k, z in enumerate((None, math.nan, math.inf), start=2):
        out = session.add(NS + k * NS // 20, z)
        assert out.status == 'missing' and out.command is not None
    assert session.estimate().covariance[1, 1] > p0


def test_failed_smoothings_count_across_restarts_and_from_a_replaced_session(monkeypatch):
    """smoothing_failures: the aligner's, those of aligners restarted since, and earlier ones."""
    from dataclasses import replace

    from tskf_ros.led.two_axis import conical_ekf

    def broken(filt, record):
        raise np.linalg.LinAlgError('not positive definite')
    monkeypatch.setattr(conical_ekf, 'smooth_window', broken)
    ekf = replace(conical_ekf.ConicalEKFConfig(), smooth_after=5, smooth_every=0)
    session = PanTiltSession(PanTiltSessionConfig(ekf=ekf), earlier_failures=3)
    assert session.smoothing_failures == 3
    for k in range(5):                          # the window ends at the 5th sample
        session.add(100 * NS + k * NS // 20, 2.5)
    assert session.smoothing_failures == 4
    assert session.add(10 * NS, 2.5).status == 'reset'   # far back in time: a new aligner
    for k in range(1, 5):
        session.add(10 * NS + k * NS // 20, 2.5)
    assert session.smoothing_failures == 5 and session.resets == 1


@pytest.mark.parametrize('stamp,reason', [(0, 'zero_stamp'), (NS, 'duplicate'),
                                          (NS - 1000, 'stale'), (2**63 - 1, 'stamp_range')])
def test_bad_stamps_are_rejected_without_a_command(stamp, reason):
    """An unset, repeated, older or impossible stamp: rejected, nothing commanded."""
    session = PanTiltSession()
    session.add(NS, 2.0)
    out = session.add(stamp, 2.0)
    assert (out.status, out.reason, out.command) == ('rejected', reason, None)


def test_backward_jump_restarts():
    """A stamp far older than the last restarts the filter (and is used)."""
    session = PanTiltSession()
    session.add(100 * NS, 2.0)
    out = session.add(10 * NS, 2.0)
    assert (out.status, out.reason) == ('reset', 'backward_jump') and session.resets == 1


def test_tilt_stays_within_its_limits():
    """Commands never take the tilt beyond tilt_limits."""
    session = PanTiltSession(PanTiltSessionConfig(joints0=(0.0, 29.0), tilt_limits=(-30, 30)))
    for k in range(1, 200):
        out = session.add(k * NS // 20, 0.0)
        if out.command is not None:
            assert -30.0 <= out.command[1] <= 30.0


def test_absurd_reading_restarts_without_publishing_nan():
    """A reading of 1e308 V: the step fails or restarts; no NaN command or estimate."""
    session = PanTiltSession()
    session.add(NS, 2.0)
    out = session.add(NS + NS // 20, 1e308)
    if out.command is not None:
        assert all(math.isfinite(v) for v in out.command)
        assert np.all(np.isfinite(out.estimate.x))


@pytest.mark.parametrize('bad', [{'method': 'spiral'}, {'start': 'sleeping'},
                                 {'joints0': (0.0, 85.0)}, {'noise': 0.0},
                                 {'dt': math.nan},
                                 {'method': 'conical_ekf', 'start': 'acquiring'}])
def test_bad_session_configs_say_why(bad):
    """Each bad setting is one AlignmentError."""
    with pytest.raises(AlignmentError):
        PanTiltSessionConfig(**bad).make_aligner()


def test_the_link_and_the_session_agree_on_the_start():
    """A session that does not start at the link's joints is refused."""
    session = PanTiltSession(PanTiltSessionConfig(joints0=(5.0, 20.0)))
    with pytest.raises(AlignmentError, match='starts at'):
        pan_tilt_closed_loop(PanTiltLinkConfig(), session, 3)
    assert PanTiltLink().joints.tolist() == [[0.0, 20.0]]


def test_with_the_supervisor_the_state_is_reported():
    """Method conical_ekf_pat, cold start: 'acquiring', no estimate before a hand-over."""
    session = PanTiltSession(PanTiltSessionConfig(method='conical_ekf_pat', start='acquiring',
                                                  noise=1.0))
    out = session.add(NS, 0.1)
    assert out.state == 'acquiring' and out.estimate is None and out.command is not None
    loop = pan_tilt_closed_loop(PanTiltLinkConfig(noise=1.0, offset0=10.0),
                                PanTiltSession(PanTiltSessionConfig(
                                    method='conical_ekf_pat', start='acquiring', noise=1.0)),
                                200, seed=3)
    states = [o.state for o in loop.outcomes if o is not None]
    assert states[-1] == 'tracking' and loop.theta()[-1] <= 15.0
