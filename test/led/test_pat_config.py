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

"""The alignment session's pointing settings (pat.*) and its supervisor, without ROS."""

import dataclasses

import numpy as np
import pytest

from tskf_ros import led
from tskf_ros.core.diagnostic_status import ERROR, OK, WARN
from tskf_ros.core.units import NS
from tskf_ros.led.alignment_config import AlignmentConfig
from tskf_ros.led.alignment_session import AlignmentSession
from tskf_ros.led.pat_config import PatConfig
from tskf_ros.led.supervisor import SupervisorConfig

T0 = 1_700_000_000 * NS
STEP = NS // 20                   # 50 ms


def test_the_defaults_are_the_supervisors():
    # the node's defaults are the Monte Carlo experiment's (SupervisorConfig's own)
    config = AlignmentConfig()
    got = config.supervisor()
    want = SupervisorConfig()
    assert got.scan == want.scan and got.detector == want.detector
    assert dataclasses.replace(got.lock, gate=0.0) == want.lock
    assert got.lock.gate == config.gate and got.max_step == want.max_step == config.max_step
    assert got.noise == pytest.approx(1.0) == want.noise      # sqrt(R_11) of Table I
    assert got.start == 'acquiring' and got.reacquire


@pytest.mark.parametrize('make, reason', [
    (lambda: AlignmentConfig(controller='lqg'), 'pat.enabled needs controller p'),
    (lambda: AlignmentConfig(max_step=2.0), 'exceeds max_step'),
    (lambda: PatConfig(start='sleeping'), 'pat.start must be one of'),
    (lambda: PatConfig(lock_low_count=30), 'low_count must be in'),
    (lambda: PatConfig(scan_first=120.0), 'wider than the search half-width'),
])
def test_a_bad_setting_is_refused_with_the_reason(make, reason):
    with pytest.raises(led.AlignmentError, match=reason):
        make()


def test_without_the_supervisor_lqg_and_a_slow_base_are_fine():
    off = PatConfig(enabled=False)
    AlignmentConfig(controller='lqg', pat=off)
    assert AlignmentSession(AlignmentConfig(max_step=2.0, pat=off)).pat_state == 'disabled'


def feed(session, k0, values):
    """Add values at stamps k0, k0 + 1, ... (50 ms); return the outcomes."""
    return [session.add(T0 + (k0 + i) * STEP, z) for i, z in enumerate(values)]


def test_light_found_then_lost_after_m_of_n_dark_samples_negative_ones_included():
    s = AlignmentSession(AlignmentConfig())
    assert s.take_transitions()[0].new == 'acquiring'
    assert s.diagnostics()[-1].level == WARN
    # a steady 2.8 V: the CUSUM (k_ref 1 V, h 4 V) crosses at the third sample
    outs = feed(s, 0, [2.8] * 3)
    assert [o.prior is None for o in outs] == [True] * 3     # no estimate while searching
    (found,) = s.take_transitions()
    assert (found.old, found.new, found.stamp_ns) == ('acquiring', 'tracking', T0 + 2 * STEP)
    outs = feed(s, 3, [2.8] * 60)
    assert all(o.prior is not None for o in outs) and s.pat_state == 'tracking'
    assert s.diagnostics()[-1].level == OK
    # the dark reads its noise, half of it negative: missing to the EKF, dark to the lock
    # test, so the 12th dark sample of the window (M = 12, N = 20) declares the loss
    dark = [-0.1, 0.1] * 10
    outs = feed(s, 63, dark)
    assert sum(o.reason == 'negative' for o in outs) == 10
    (lost,) = s.take_transitions()
    assert (lost.new, lost.reason, lost.stamp_ns) == ('lost', 'loss declared, held',
                                                      T0 + 74 * STEP)
    assert s.pointing.losses == 1 and s.pointing.last_loss_ns == T0 + 74 * STEP
    status = s.diagnostics()[-1]
    assert status.level == ERROR and status.as_dict()['Losses'] == '1'


def test_acquire_forces_a_search_and_reset_starts_over():
    s = AlignmentSession(AlignmentConfig())
    feed(s, 0, [2.8] * 10)
    assert s.pat_state == 'tracking'
    s.take_transitions()
    assert s.acquire()
    (t,) = s.take_transitions()
    assert (t.old, t.new, t.reason) == ('tracking', 'acquiring', 'acquire requested')
    assert s.pointing.requests == 1
    feed(s, 10, [2.8] * 3)
    assert s.pat_state == 'tracking' and s.pointing.acquisitions == 2
    s.reset('service')
    assert s.pat_state == 'acquiring'
    assert s.take_transitions()[-1].reason == 'restarted (service)'


@pytest.mark.parametrize('clip, P0', [(False, (100.0, 0.0, 0.0, 1000.0)),
                                      (True, (4.0, 0.0, 0.0, 25.0))])
def test_start_tracking_is_the_papers_start_with_the_supervisor_watching(clip, P0):
    s = AlignmentSession(AlignmentConfig(pat=PatConfig(start='tracking', clip_prior=clip)))
    out = feed(s, 0, [2.8])[0]
    # the EKF from Table I's x0 and P0 (clipped to [0.01, 4] V^2 and [4, 25] deg^2 with
    # clip_prior), as the bare EKF started from that P0
    bare = AlignmentSession(AlignmentConfig(P0=P0, pat=PatConfig(enabled=False)))
    ref = feed(bare, 0, [2.8])[0]
    np.testing.assert_allclose(out.posterior.x, ref.posterior.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.posterior.P, ref.posterior.P, rtol=1e-12, atol=1e-12)
    assert out.command == pytest.approx(ref.command, abs=1e-12)
    assert s.pat_state == 'tracking'


def test_a_loss_is_held_with_estimates_and_tracked_again():
    # a dark spell is declared but held: the EKF keeps steering and publishing, and the
    # run is tracking again once a window has few low samples, with no new hand-over
    s = AlignmentSession(AlignmentConfig())
    feed(s, 0, [1.5] * 80)
    assert [t.new for t in s.take_transitions()] == ['acquiring', 'tracking']
    held = feed(s, 80, [0.0] * 20)
    (lost,) = s.take_transitions()
    assert (lost.new, lost.reason) == ('lost', 'loss declared, held')
    assert s.supervisor.held[0] > 0 and s.pat_state == 'lost'
    assert all(o.posterior is not None for o in held)            # still estimating
    back = feed(s, 100, [1.5] * 40)
    (found,) = s.take_transitions()
    assert (found.old, found.new, found.reason) == ('lost', 'tracking', 'light back after a hold')
    assert s.pointing.reacquisitions == 1 and s.supervisor.handovers[0] == 1
    assert all(o.posterior is not None for o in back)
