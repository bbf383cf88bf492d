"""
The estimator session's diagnostics: a level, one message and the counters as key values.

ERROR: the filter re-initialised itself, or the input went silent (InputRate); WARN: a gap
longer than max_gap, a sampling interval that breaks observability (Fang & de Callafon
Section III), or an input rate too low; OK otherwise.
"""

from typing import NamedTuple, Optional, Union

from tskf_ros.core.input_rate import InputRate, report_head, worst
from tskf_ros.core.units import NS
from tskf_ros.owc.session.config import EstimatorConfig
from tskf_ros.owc.session.outcome import FloatArray, REJECT_REASONS, RESET_REASONS, Stats

# diagnostics list at most this many of the sampling intervals seen
INTERVALS_SHOWN = 20
# and this many of the gap lengths
GAPS_SHOWN = 20

Value = Union[int, float, str]


class Diagnostics(NamedTuple):
    """A diagnostics status: level 'OK', 'WARN' or 'ERROR', message, key values."""

    level: str
    message: str
    values: dict[str, Value]


class SessionState(NamedTuple):
    """What the report shows besides the counters: the filter's state and the input."""

    points: int                 # in the history
    u: FloatArray               # the input in force
    P: FloatArray               # the filter's covariance
    health_error: str           # why the filter re-initialised itself since the last report


def report(st: Stats, cfg: EstimatorConfig, rate: InputRate, state: SessionState,
           now_ns: Optional[int]) -> Diagnostics:
    """Return the diagnostics of a session; with now_ns the input rate is judged too."""
    level, msgs, values = report_head(
        rate, now_ns, state.health_error and
        f'filter re-initialised itself: {state.health_error}')
    if st.gaps_over_bound:
        level = worst(level, 'WARN')
        msgs.append(f'{st.gaps_over_bound} gap(s) longer than max_gap = {cfg.max_gap} s')
    if st.rejected_since:
        msgs.append(f'{st.rejected_since} sample(s) rejected')
    if st.interval_warnings:
        level = worst(level, 'WARN')
        msgs.append('sampling interval(s) ' + ', '.join(
            str(w.kappa) for w in st.interval_warnings) + ' break observability (Fang & '
            'de Callafon Section III)')
    lengths = list(st.gaps.values())
    seen = [str(k) for k in sorted(st.intervals)]
    shown = seen if len(seen) <= INTERVALS_SHOWN else (
        seen[:INTERVALS_SHOWN // 2] + ['...'] + seen[-INTERVALS_SHOWN // 2:])
    warnings = st.interval_warnings[:INTERVALS_SHOWN]
    values.update({
        'received': st.received, 'accepted': st.accepted, 'inserted_late': st.inserted,
        'inputs_received': st.inputs_received, 'inputs_accepted': st.inputs_accepted,
        'input_in_force': ' '.join(f'{v:g}' for v in state.u),
        'points_in_history': state.points,
        'mu_current_s': st.mu_current, 'mu_max_s': st.mu_max,
        'gaps': st.gaps_total,
        'gap_max_s': max(lengths) if lengths else 0.0,
        'gap_lengths_s': ' '.join(f'{j:g}' for j in lengths[-GAPS_SHOWN:]),
        'covariance_trace': st.covariance_trace,
        'last_stamp_s': st.last_stamp_ns / NS,
        'transition': cfg.transition,
        'intervals_seen_periods': ' '.join(shown),
        'intervals_seen_count': len(seen),
        'interval_warnings': ' | '.join(f'{w.kappa}: {w.why}' for w in warnings),
    })
    if st.peak_bounds is not None:
        # Theorem 2 next to the covariance the filter runs (scalar models only)
        values['theorem2_peak_bound_low'] = st.peak_bounds.low
        values['theorem2_peak_bound_high'] = st.peak_bounds.high
        values['covariance'] = float(state.P[0, 0])
    for reason in REJECT_REASONS:
        values[f'rejected_{reason}'] = st.rejected[reason]
    for reason in RESET_REASONS:
        values[f'resets_{reason}'] = st.resets[reason]
    return Diagnostics(level, '; '.join(msgs) or 'ok', values)
