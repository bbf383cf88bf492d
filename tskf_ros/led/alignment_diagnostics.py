"""
The alignment session's diagnostic tasks besides its input's: the aligner and time scale.

aligner: ERROR when it restarted itself since the last update; WARN when the EKF lost the
transmitter (x1hat <= 0); OK otherwise, saying when the loop is paused (~/enable false);
samples, commands and missing / rejected samples and restarts by reason.  time scale:
WARN on a gap longer than max_gap since the last update; gaps and mu = interval / dt.
"""

from typing import Optional, TYPE_CHECKING

import numpy as np

from tskf_ros.core.diagnostic_status import ERROR, OK, Status, TIME_SCALE, WARN
from tskf_ros.core.units import NS
from tskf_ros.led.alignment_config import AlignmentConfig
from tskf_ros.led.intensity_model import FloatArray

if TYPE_CHECKING:
    from tskf_ros.led.alignment_session import AlignStats

ALIGNER = 'aligner'


def aligner_status(st: 'AlignStats', cfg: AlignmentConfig, base: float, health_error: str,
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


def time_scale(st: 'AlignStats', cfg: AlignmentConfig) -> Status:
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


def status_line(st: 'AlignStats', rate: float, base: float, paused: bool,
                x: Optional[FloatArray]) -> str:
    """Return the one-line status the node logs: rate, gaps, last command, estimate, resets."""
    estimate = '' if x is None else ', estimate [' + ' '.join(
        f'{v:.4g}' for v in x.tolist()) + ']'
    return (f'{rate:.3g} Hz in{" (paused)" if paused else ""}, {st.received} received, '
            f'{st.used} used; {st.gaps} gap(s) (longest {st.gap_max:g} s); base '
            f'{base:.4g} deg{estimate}; {sum(st.resets.values())} restart(s)')
