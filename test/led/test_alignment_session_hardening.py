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
The alignment session under absurd inputs: neither a crash nor a wedged filter.

Each test states the case that failed before its fix.  The session is driven directly
(no DDS); the node's cases are in test/nodes/, the estimator session's in test/owc/session/.
"""

import numpy as np
import pytest

from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.led.alignment_session import AlignmentConfig, AlignmentSession
from tskf_ros.led.pat_config import PatConfig

T0 = 1_700_000_000 * NS


# -- the alignment session ---------------------------------------------------------------

def aligner(**extra):
    # the scanning EKF alone (pat.enabled false): the supervisor's cases are below
    return AlignmentSession(AlignmentConfig(**{'pat': PatConfig(enabled=False), **extra}))


def test_alignment_gates_a_1e308_intensity_and_the_base_stays_in_its_limits():
    # before: the base command went to about -8e305 rad, and stayed there
    a = aligner()
    stamps = [T0 + k * NS // 20 for k in range(400)]
    outs = []
    for k, t in enumerate(stamps):
        z = 1e308 if k == 200 else 2.0
        outs.append(a.add(t, z))
    # beyond state_limit (1e6 V): no light the aligner could follow, missing before the gate
    assert outs[200].status == 'missing' and outs[200].reason == 'out_of_range'
    commands = [o.command for o in outs if o.command is not None]
    assert all(-360.0 <= c <= 360.0 for c in commands)
    turns = np.abs(np.diff([0.0] + commands))
    assert turns.max() <= 45.0 + 1e-9
    assert outs[-1].status == 'used'


def test_alignment_commands_are_clamped_and_the_ekf_told():
    a = aligner(max_step=1.0, base_limits=(-3.0, 3.0), x0=(2.0, 20.0))
    outs = [a.add(T0 + k * NS // 20, 2.0) for k in range(50)]
    cmds = [o.command for o in outs]
    assert all(-3.0 - 1e-12 <= c <= 3.0 + 1e-12 for c in cmds)
    assert max(abs(b - c) for b, c in zip([0.0] + cmds, cmds)) <= 1.0 + 1e-12
    assert int(a.diagnostics()[0].as_dict()['Commands clamped']) > 0
    with pytest.raises(ValueError, match='base_initial'):
        AlignmentConfig(base_initial=10.0, base_limits=(-3.0, 3.0))


@pytest.mark.parametrize('bad', [1e308, 1e200, float('inf'), -1e308])
def test_the_supervisor_survives_absurd_intensities_while_searching(bad):
    # three absurd readings in the dark of a cold search, then light from sample 100:
    # finite commands within the joint limits, and tracking at the end
    a = AlignmentSession(AlignmentConfig())
    outs = [a.add(T0 + k * NS // 20, bad if 5 <= k < 8 else (2.0 if k > 100 else 0.0))
            for k in range(400)]
    commands = [o.command for o in outs if o.command is not None]
    assert len(commands) == 400 - a.stats.rejected.total()
    assert all(-360.0 <= c <= 360.0 for c in commands)
    assert a.pat_state == 'tracking'


def test_alignment_rejects_stamps_beyond_int32_seconds():
    a = AlignmentSession(AlignmentConfig())
    assert a.add(MAX_STAMP_NS + 1, 1.0).reason == 'stamp_range'


def test_alignment_restarts_itself_on_an_absurd_state_and_reports_error():
    a = aligner(gate=0.0)                 # no gate: 9e5 V (within state_limit) reaches the EKF
    outs = [a.add(T0 + k * NS // 20, 2.0) for k in range(3)]
    outs.append(a.add(T0 + 3 * NS // 20, 9e5))
    assert outs[-1].reason == 'filter_error' and 'state_limit' in outs[-1].message
    aligner_status = a.diagnostics()[0]
    assert aligner_status.level == 2
    assert aligner_status.as_dict()['Resets (state_health)'] == '1'


# -- the pointing supervisor's input (each case failed over DDS before its fix) -----------

def pointing_loop(steps, session=None, *, inject=None, every=None, phi0=60.0, seed=11):
    """
    Run the simulated link (light phi0 deg off) against a session with the supervisor.

    inject(k, reading) may replace sample k's reading; every(k) runs before sample k (a
    service call).  Returns (session, the outcomes, the plant's angle of incidence).
    """
    from tskf_ros.led.led_link import LedLink, LedLinkConfig
    session = session or AlignmentSession(AlignmentConfig())
    plant = LedLink(LedLinkConfig(phi0=phi0, seed=seed))
    outs, phi = [], []
    for k in range(steps):
        if every is not None:
            every(k)
        s = plant.sample()
        z = s.reading if inject is None else inject(k, s.reading)
        out = session.add(T0 + k * NS // 20, z)
        outs.append(out)
        phi.append(s.phi)
        if out.command is not None:
            plant.command(out.command)
    return session, outs, np.array(phi)


def test_repeated_acquire_requests_do_not_walk_the_search_away():
    # before: ten requests once a second while acquiring moved the base to 360 deg, and
    # 30 s later it still searched there with the light at -60 deg
    def request(k):
        if 20 <= k < 220 and k % 20 == 0 and session.pat_state == 'acquiring':
            session.acquire()
    session = AlignmentSession(AlignmentConfig())
    session, outs, phi = pointing_loop(220 + 30 * 20, session, every=request)
    bases = np.array([o.command for o in outs if o.command is not None])
    assert np.abs(bases[:220]).max() <= 90.0 + 1e-9      # within the cold search's +-90
    assert session.pat_state == 'tracking'
    assert np.abs(phi[-20:]).max() <= 15.0


@pytest.mark.parametrize('bad', [1e308, -1e308, 1e300, 1e7, -1e7])
def test_one_absurd_reading_while_searching_is_missing_and_hands_nothing_over(bad):
    # before: one 1e308 V sample in the dark gave acquiring -> tracking -> acquiring
    session = AlignmentSession(AlignmentConfig())
    outs = [session.add(T0 + k * NS // 20, bad if k == 30 else 0.0) for k in range(60)]
    assert outs[30].status == 'missing' and outs[30].reason == 'out_of_range'
    assert session.pat_state == 'acquiring' and session.pointing.transitions == 0
    assert session.pointing.acquisitions == 0 and not session.stats.resets


@pytest.mark.parametrize('bad', [1e308, -1e308, 1e300, -0.5, float('nan')])
def test_one_absurd_reading_while_tracking_keeps_the_lock(bad):
    # before: one -1e308 or 1e300 V sample threw the lock ("EKF state or covariance
    # 3.02e+307 beyond state_limit"; "the EKF estimate is not finite")
    first = {}

    def inject(k, z):
        if session.pat_state == 'tracking' and 'at' not in first:
            first['at'] = k
        return bad if k == first.get('at', -1) + 60 else z
    session = AlignmentSession(AlignmentConfig())
    session, outs, phi = pointing_loop(400, session, inject=inject)
    k = first['at'] + 60
    assert outs[k].status == 'missing'
    assert session.pat_state == 'tracking' and session.pointing.losses == 0
    assert not session.stats.resets and session.pointing.transitions == 1
    # a missing sample leaves the corrected estimate the predicted one (the -0.5 V case
    # moved x1hat 2.993 -> 2.137 V and P11 0.597 -> 0.266 before)
    np.testing.assert_array_equal(outs[k].posterior.x, outs[k].prior.x)
    np.testing.assert_array_equal(outs[k].posterior.P, outs[k].prior.P)


def test_a_change_of_gate_noise_or_max_step_reaches_the_supervisor_in_place():
    # before: 'new parameters in use', but the NIS band kept the old gate until ~/reset
    from tskf_ros.led.lock_detector import nis_band
    session, outs, _ = pointing_loop(200)
    assert session.pat_state == 'tracking'
    old = session.config
    new = AlignmentConfig(gate=2.0, R=(0.09, 0.0, 0.0, 0.09), max_step=10.0)
    assert session.reconfigure(new) == 'new parameters in use'
    sup = session.supervisor
    assert session.pat_state == 'tracking' and sup.config == new.supervisor()
    assert (sup.config.lock.gate, sup.config.noise, sup.config.max_step) == (2.0, 0.3, 10.0)
    window = old.pat.lock_window
    want = [nis_band(k, old.pat.lock_nis_alpha, 2.0) for k in range(window + 1)]
    np.testing.assert_allclose(sup.lock.bands, want, rtol=1e-12, atol=0)
    assert not session.stats.resets


def test_a_search_that_runs_into_a_joint_limit_turns_there():
    # a cold search from 80 deg with limits +-100: the first leg (to 170) cannot end
    config = AlignmentConfig(base_initial=80.0, base_limits=(-100.0, 100.0))
    session = AlignmentSession(config)
    outs = [session.add(T0 + k * NS // 20, 0.0) for k in range(200)]
    bases = [o.command for o in outs]
    assert max(bases) == 100.0 and min(bases) < 0.0       # it turned and swept back


def test_samples_lost_in_a_burst_are_counted_by_their_stamps():
    # 100 samples, 30 of them (in three runs) never arrive: round(mu) - 1 per gap
    session = AlignmentSession(AlignmentConfig(pat=PatConfig(enabled=False)))
    lost = set(range(10, 20)) | set(range(40, 45)) | set(range(60, 75))
    for k in range(100):
        if k not in lost:
            session.add(T0 + k * NS // 20, 2.0)
    values = session.diagnostics()[0].as_dict()
    assert values['Samples missed (stamps)'] == str(len(lost))
    assert session.stats.gaps == 3
