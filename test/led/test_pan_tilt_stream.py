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

"""The two-axis stream: the one-axis session's checks and counters around the pan-tilt session."""

from dataclasses import replace

import numpy as np
import pytest

from tskf_ros.core.diagnostic_status import OK, WARN
from tskf_ros.core.units import NS
from tskf_ros.led.pan_tilt_stream import PanTiltStream, PanTiltStreamConfig
from tskf_ros.led.two_axis.conical_ekf import ConicalEKFConfig, transition
from tskf_ros.led.two_axis.pan_tilt_session import PanTiltSession, PanTiltSessionConfig

DT_NS = 50_000_000


def stream(**extra):
    """Return a stream of the default conical-scan EKF session."""
    return PanTiltStream(PanTiltStreamConfig(PanTiltSessionConfig(), **extra))


def test_used_samples_are_the_bare_sessions_steps():
    s, bare = stream(), PanTiltSession(PanTiltSessionConfig())
    rng = np.random.default_rng(7)
    for k, z in enumerate(2.0 + 0.2 * rng.standard_normal(30)):
        got, want = s.add(NS + k * DT_NS, z), bare.add(NS + k * DT_NS, z)
        assert got.outcome.command == want.command
        np.testing.assert_array_equal(got.outcome.estimate.x, want.estimate.x)
        assert got.mu == pytest.approx(0.0 if k == 0 else 0.05, abs=1e-12)
    assert s.stats.received == s.stats.used == s.stats.commands == 30


@pytest.mark.parametrize('z, extra, reason', [
    (-0.3, {}, 'negative'),
    (7.0, {'intensity_range': (0.0, 5.0)}, 'out_of_range'),
    (float('nan'), {}, 'non_finite'),
])
def test_a_bad_reading_is_a_missing_sample_the_filter_predicts_over(z, extra, reason):
    s, bare = stream(**extra), PanTiltSession(PanTiltSessionConfig())
    for k, value in enumerate([2.5, 2.4, z, 2.6]):
        got = s.add(NS + k * DT_NS, value)
        want = bare.add(NS + k * DT_NS, None if k == 2 else value)
        assert got.outcome.command == want.command
    assert s.stats.missing[reason] == 1 and s.stats.used == 3 and s.stats.commands == 4


def test_gaps_rejections_and_a_backward_jump_are_counted():
    s = stream(max_gap=0.1)
    for k in (0, 1, 5, 5, 4):
        s.add(NS + k * DT_NS, 2.5)
    st = s.stats
    assert st.gaps == 1 and st.missed == 3 and st.gap_max == pytest.approx(0.2)
    assert st.rejected['duplicate'] == 1 and st.rejected['stale'] == 1
    s.add(100 * NS, 2.5)
    s.add(NS, 2.5)                       # 99 s back: beyond max_backward, a restart
    assert st.resets['backward_jump'] == 1
    names = [d.name for d in s.diagnostics(now_ns=101 * NS)]
    assert names == ['input frequency', 'timestamp delay', 'aligner', 'time scale']
    level = {d.name: d.level for d in s.diagnostics()}
    assert level['time scale'] == 0     # the long gap was reported once, by the first call


def test_the_prior_is_the_prediction_from_the_last_posterior():
    # P^f_k = F(mu) P_{k-1} F(mu)^T + mu Q; x1 and the drifts b carry over (F leaves them)
    s = stream()
    Q = np.diag(s.session.tracker.config.Q)
    prev = None
    for k in (0, 1, 2, 5, 6):                  # a gap of mu = 3 after sample 2
        step = s.add(NS + k * DT_NS, 2.5)
        assert step.prior is not None
        x_prior, P_prior = step.prior
        if prev is not None:
            mu = step.mu / 0.05
            F = transition(mu)
            np.testing.assert_allclose(P_prior, F @ prev.P @ F.T + mu * Q, rtol=1e-12,
                                       atol=1e-12)
            np.testing.assert_allclose(x_prior[[0, 3, 4]], prev.x[[0, 3, 4]], rtol=0,
                                       atol=1e-12)
        prev = step.outcome.estimate


def test_a_failed_smoothing_warns_once_and_is_counted_across_restarts(monkeypatch):
    """The window's smoothing raising: the aligner warns on the next report, not after."""
    from tskf_ros.led.two_axis import conical_ekf

    def broken(filt, record):
        raise np.linalg.LinAlgError('not positive definite')
    monkeypatch.setattr(conical_ekf, 'smooth_window', broken)
    ekf = replace(ConicalEKFConfig(), smooth_after=5, smooth_every=4)
    s = PanTiltStream(PanTiltStreamConfig(PanTiltSessionConfig(ekf=ekf)))
    k = 0
    for k in range(9):                     # windows end at the 5th and the 9th sample
        s.add(NS + k * DT_NS, 2.5)
    first = {d.name: d for d in s.diagnostics()}['aligner']
    assert first.as_dict()['Smoothing failures'] == '2'
    assert first.level == WARN and '2 smoothing(s)' in first.message
    again = {d.name: d for d in s.diagnostics()}['aligner']
    assert again.level == OK and again.as_dict()['Smoothing failures'] == '2'
    s.reset('clock_jump')                  # a new aligner: its count adds to the earlier
    for j in range(1, 6):
        s.add(NS + (k + j) * DT_NS, 2.5)
    after = {d.name: d for d in s.diagnostics()}['aligner']
    assert after.as_dict()['Smoothing failures'] == '3' and '1 smoothing(s)' in after.message
    # not consumed: reported again; a reconfiguration keeps the count and the warning
    for j in range(6, 10):                 # the new aligner's window ends at its 9th sample
        s.add(NS + (k + j) * DT_NS, 2.5)
    peek = {d.name: d for d in s.diagnostics(consume=False)}['aligner']
    assert peek.as_dict()['Smoothing failures'] == '4' and '1 smoothing(s)' in peek.message
    s.reconfigure(s.config)
    moved = {d.name: d for d in s.diagnostics()}['aligner']
    assert moved.as_dict()['Smoothing failures'] == '4' and '1 smoothing(s)' in moved.message
    assert {d.name: d for d in s.diagnostics()}['aligner'].level == OK
