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
The estimator session's diagnostic tasks besides its input's: filter health and time scale.

filter health: ERROR when the filter re-initialised itself (state_health) since the last
update, else OK; the samples, rejections and resets by reason.  time scale: WARN on a gap
longer than max_gap or a sampling interval that breaks observability (Fang & de Callafon
Section III) since the last update, else OK; gaps, J, mu and the intervals seen.
"""

from typing import NamedTuple

from tskf_ros.core.diagnostic_status import ERROR, OK, Status, TIME_SCALE, WARN
from tskf_ros.core.units import NS
from tskf_ros.owc.session.config import EstimatorConfig
from tskf_ros.owc.session.outcome import FloatArray, REJECT_REASONS, RESET_REASONS, Stats

# the time scale task lists at most this many of the sampling intervals seen
INTERVALS_SHOWN = 20
# and this many of the gap lengths
GAPS_SHOWN = 20
FILTER_HEALTH = 'filter health'


class SessionState(NamedTuple):
    """What the report shows besides the counters: the filter's state and the input."""

    points: int                 # in the history
    u: FloatArray               # the input in force
    P: FloatArray               # the filter's covariance
    health_error: str           # why the filter re-initialised itself since the last report


def filter_health(st: Stats, state: SessionState) -> Status:
    """Return the 'filter health' status: samples, rejections and resets by reason."""
    stat = Status(FILTER_HEALTH)
    if state.health_error:
        stat.summary(ERROR, f'filter re-initialised itself: {state.health_error}')
    elif st.rejected_since:
        stat.summary(OK, f'{st.rejected_since} sample(s) rejected since the last update')
    else:
        stat.summary(OK, 'ok')
    for key, value in (('Samples received', st.received),
                       ('Messages lost (transport)', st.messages_lost),
                       ('Samples accepted', st.accepted),
                       ('Samples inserted late', st.inserted),
                       ('Inputs received', st.inputs_received),
                       ('Inputs accepted', st.inputs_accepted),
                       ('Input in force', ' '.join(f'{v:g}' for v in state.u)),
                       ('Points in history', state.points),
                       ('Covariance trace', st.covariance_trace),
                       ('Rejections', sum(st.rejected.values())),
                       ('Resets', sum(st.resets.values()))):
        stat.add(key, value)
    for reason in REJECT_REASONS:
        stat.add(f'Rejected ({reason})', st.rejected[reason])
    for reason in RESET_REASONS:
        stat.add(f'Resets ({reason})', st.resets[reason])
    return stat


def time_scale(st: Stats, cfg: EstimatorConfig, P: FloatArray) -> Status:
    """Return the 'time scale' status: gaps, J, mu and the sampling intervals seen."""
    stat = Status(TIME_SCALE)
    stat.summary(OK, 'ok')
    if st.gaps_over_bound:
        stat.merge_summary(WARN, f'{st.gaps_over_bound} gap(s) longer than max_gap = '
                           f'{cfg.max_gap:g} s')
    if st.interval_warnings:
        stat.merge_summary(WARN, 'sampling interval(s) ' + ', '.join(
            str(w.kappa) for w in st.interval_warnings) + ' break observability (Fang & '
            'de Callafon Section III)')
    lengths = list(st.gaps.values())
    seen = [str(k) for k in sorted(st.intervals)]
    shown = seen if len(seen) <= INTERVALS_SHOWN else (
        seen[:INTERVALS_SHOWN // 2] + ['...'] + seen[-INTERVALS_SHOWN // 2:])
    warnings = st.interval_warnings[:INTERVALS_SHOWN]
    for key, value in (('Gaps', st.gaps_total),
                       ('Longest gap J (s)', max(lengths) if lengths else 0.0),
                       ('Last gaps J (s)', ' '.join(f'{j:g}' for j in lengths[-GAPS_SHOWN:])),
                       ('mu current (s)', st.mu_current), ('mu max (s)', st.mu_max),
                       ('Last stamp (s)', st.last_stamp_ns / NS),
                       ('Transition', cfg.transition),
                       ('Intervals seen (periods)', ' '.join(shown)),
                       ('Intervals seen (count)', len(seen)),
                       ('Interval warnings', ' | '.join(f'{w.kappa}: {w.why}'
                                                        for w in warnings))):
        stat.add(key, value)
    if st.peak_bounds is not None:
        # Theorem 2 next to the covariance the filter runs (scalar models only)
        stat.add('Theorem 2 peak bound (low)', st.peak_bounds.low)
        stat.add('Theorem 2 peak bound (high)', st.peak_bounds.high)
        stat.add('Covariance', float(P[0, 0]))
    return stat


def status_line(st: Stats, frequency_hz: float, x: FloatArray) -> str:
    """Return the one-line status the node logs: rate, gaps, last estimate, resets."""
    resets = sum(st.resets.values())
    estimate = ' '.join(f'{v:.4g}' for v in x.ravel().tolist())
    return (f'{frequency_hz:.3g} Hz in, {st.received} received, {st.accepted} accepted, '
            f'{sum(st.rejected.values())} rejected; {st.gaps_total} gap(s) (longest '
            f'{max(st.gaps.values(), default=0.0):g} s); last estimate [{estimate}] at '
            f'{st.last_stamp_ns / NS:.3f} s; {resets} reset(s)')
