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
The alignment session's diagnostic tasks besides its input's: aligner, time scale, pointing.

aligner: ERROR when it restarted itself since the last update; WARN when the EKF lost the
transmitter (x1hat <= 0); OK otherwise, saying when the loop is paused (~/enable false);
samples, commands and missing / rejected samples and restarts by reason.  time scale:
WARN on a gap longer than max_gap since the last update; gaps and mu = interval / dt.
pointing (with the supervisor): OK tracking, WARN acquiring, ERROR lost, OK paused; the
state, its time, the transitions, losses and re-acquisitions, and the lock tests.
"""

import math
from typing import Optional, Protocol, TYPE_CHECKING

import numpy as np

from tskf_ros.core.diagnostic_status import ERROR, OK, Status, TIME_SCALE, WARN
from tskf_ros.core.units import NS
from tskf_ros.led.intensity_model import FloatArray

from tskf_ros.led.lock_detector import LockVerdict
from tskf_ros.led.pointing_stats import PointingStats

if TYPE_CHECKING:
    from tskf_ros.led.alignment_session import AlignStats

ALIGNER = 'aligner'
POINTING = 'pointing'
# the level of each supervisor state: tracking is the loop working, acquiring is the
# search before it works (expected at start), lost is a link that worked and is gone
POINTING_LEVELS = {'tracking': OK, 'acquiring': WARN, 'lost': ERROR}


class DiagnosedConfig(Protocol):
    """What the tasks read of a session's config (AlignmentConfig, the two-axis one)."""

    @property
    def algorithm(self) -> str:
        """Return the aligner's name."""

    @property
    def max_gap(self) -> float:
        """Return the s beyond which a gap warns."""


def aligner_status(st: 'AlignStats', cfg: DiagnosedConfig, base: float, health_error: str,
                   ekf_state: Optional[tuple[FloatArray, FloatArray]], paused: bool,
                   reasons: tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]
                   ) -> Status:
    """Return the 'aligner' status of a session's AlignStats st (see the module docstring)."""
    missing, rejected, resets = reasons
    stat = Status(ALIGNER)
    if paused:
        stat.summary(OK, f'paused (~/enable false): {st.paused} sample(s) received, not used')
    elif st.bad_since:
        stat.summary(OK, f'{st.bad_since} sample(s) missing or rejected since the last update')
    else:
        stat.summary(OK, 'ok')
    if health_error:
        stat.merge_summary(ERROR, f'aligner restarted itself: {health_error}')
    for key, value in (('Algorithm', cfg.algorithm), ('Paused', 'yes' if paused else 'no'),
                       ('Samples received', st.received),
                       ('Samples missed (stamps)', st.missed),
                       ('Messages lost (transport)', st.messages_lost),
                       ('Samples received while paused', st.paused),
                       ('Samples used', st.used), ('Commands', st.commands),
                       ('Commands clamped', st.clamped), ('Base command (deg)', base)):
        stat.add(key, value)
    for reason in missing:
        stat.add(f'Missing ({reason})', st.missing[reason])
    for reason in rejected:
        stat.add(f'Rejected ({reason})', st.rejected[reason])
    for reason in resets:
        stat.add(f'Resets ({reason})', st.resets[reason])
    if ekf_state is not None:
        x, P = ekf_state
        stat.add('x1 estimate (V)', float(x[0]))
        stat.add('x2 estimate (deg)', float(x[1]))
        stat.add('Covariance trace', float(np.trace(P)))
        stat.add('Singular updates', st.singular)
        if st.used and not x[0] > 0:
            stat.merge_summary(WARN, f'x1hat = {x[0]:.3g} <= 0: the EKF has lost the '
                               'transmitter')
    return stat


def time_scale(st: 'AlignStats', cfg: DiagnosedConfig) -> Status:
    """Return the 'time scale' status: gaps and mu of the intensity stream."""
    stat = Status(TIME_SCALE)
    stat.summary(OK, 'ok')
    if st.gaps_over_bound:
        stat.merge_summary(WARN, f'{st.gaps_over_bound} gap(s) longer than max_gap = '
                           f'{cfg.max_gap:g} s')
    for key, value in (('Gaps', st.gaps), ('Longest gap (s)', st.gap_max),
                       ('mu current', st.mu_current), ('mu max', st.mu_max),
                       ('Last stamp (s)', st.last_stamp_ns / NS)):
        stat.add(key, value)
    return stat


def pointing_status(p: PointingStats, verdict: Optional[LockVerdict], paused: bool,
                    last_stamp_ns: int) -> Status:
    """Return the 'pointing' status of the supervisor (see the module docstring)."""
    stat = Status(POINTING)
    if paused:
        stat.summary(OK, f'paused (~/enable false) while {p.state}')
    else:
        stat.summary(POINTING_LEVELS.get(p.state, OK), p.state)
    last_loss = 'never' if p.last_loss_ns is None else f'{p.last_loss_ns / NS:.3f}'
    for key, value in (('State', p.state),
                       ('Time in state (s)', p.time_in_state(last_stamp_ns)),
                       ('Transitions', p.transitions), ('Acquisitions', p.acquisitions),
                       ('Losses', p.losses), ('Re-acquisitions', p.reacquisitions),
                       ('Acquire requests', p.requests), ('Last loss (stamp, s)', last_loss)):
        stat.add(key, value)
    if verdict is not None:
        stat.add('Low samples in the lock window', int(verdict.low[0]))
        for key, value in (('Windowed NIS', float(verdict.nis[0])),
                           ('NIS band', float(verdict.band[0]))):
            stat.add(key, value if math.isfinite(value) else 'none')
    return stat


def status_line(st: 'AlignStats', rate: float, base: float, paused: bool,
                x: Optional[FloatArray], pat_state: str = 'disabled',
                tilt: Optional[float] = None) -> str:
    """Return the one-line status the node logs: rate, gaps, command, estimate, state."""
    estimate = '' if x is None else ', estimate [' + ' '.join(
        f'{v:.4g}' for v in x.tolist()) + ']'
    state = '' if pat_state == 'disabled' else f'; {pat_state}'
    # two axes: base is the pan joint's command
    command = (f'base {base:.4g} deg' if tilt is None else
               f'pan {base:.4g} deg, tilt {tilt:.4g} deg')
    return (f'{rate:.3g} Hz in{" (paused)" if paused else ""}, {st.received} received, '
            f'{st.used} used; {st.gaps} gap(s) (longest {st.gap_max:g} s); '
            f'{command}{estimate}; {sum(st.resets.values())} restart(s){state}')
