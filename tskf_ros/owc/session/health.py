"""
Health of a filter state and of a step: finite, bounded and positive semi-definite.

    healthy (x, P):  x, P finite,  max_i |x_i| <= state_limit,  trace P <= state_limit^2
    sound step:      x(t|t), P(t|t) finite,  P(t|t) and P(sigma(t)) PSD; the filter itself
                     refuses a non-finite x(sigma(t)), P(sigma(t))
"""

import math
from typing import NamedTuple

import numpy as np

from tskf_ros.core.timescale_kalman import FilterError, is_psd, StepResult
from tskf_ros.owc.session.outcome import FloatArray


class Health(NamedTuple):
    """Why a finite (x, P) is absurd ('' if it is not), and trace P."""

    why: str
    trace: float


def finite(*arrays: FloatArray) -> bool:
    """Tell whether all entries are finite; on plain floats for the few of a small state."""
    for a in arrays:
        if a.size > 16:
            if not np.isfinite(a).all():
                return False
        elif not all(map(math.isfinite, a.ravel().tolist())):
            return False
    return True


def health(x: FloatArray, P: FloatArray, limit: float) -> Health:
    """
    Return why a finite (x, P) is absurd, or '', and trace P.

    Absurd: |x_i| or sqrt(trace P) beyond limit.  On plain floats: numpy's reductions
    cost more than the work on the few entries of a state.
    """
    if x.size == 1:
        big, trace = abs(x.item()), P.item()
    else:
        big = max(map(abs, x.tolist())) if x.size else 0.0
        trace = P.trace().item() if P.shape[0] > 2 else sum(P.diagonal().tolist())
    if big > limit:
        return Health(f'|x| = {big:.3g} > state_limit = {limit:g}', math.nan)
    if not trace <= limit * limit:
        return Health(f'sqrt(trace P) = {math.sqrt(max(trace, 0.0)):.3g} > state_limit = '
                      f'{limit:g}', trace)
    return Health('', trace)


def unhealthy(x: FloatArray, P: FloatArray, limit: float) -> str:
    """Return why (x, P) is absurd (non-finite, or beyond limit), or '' if it is not."""
    if not finite(x, P):
        return 'a non-finite state or covariance'
    return health(x, P, limit).why


class StateLimitError(FilterError):
    """A step whose state is finite but beyond state_limit: absurd."""


def checked(res: StepResult, limit: float) -> float:
    """
    Return trace P(sigma(t)) of a sound step; raise FilterError if it is not sound.

    Sound: what the filter does not check itself, x(t|t), P(t|t) finite and both
    covariances positive semi-definite; and the predictor healthy (StateLimitError).
    P(t|t) of n > 1 is symmetrised in res.
    """
    P_c = res.P_corrected
    if P_c.shape[0] == 1:
        ok = math.isfinite(res.x_corrected.item()) and math.isfinite(P_c.item())
    else:
        P_c = P_c + P_c.T
        P_c *= 0.5
        res.P_corrected = P_c
        ok = finite(res.x_corrected, P_c)
    if not ok:
        raise FilterError(f'non-finite estimate at mu = {res.mu}')
    if not is_psd(P_c):
        raise FilterError(f'P(t|t) lost positive semi-definiteness at mu = {res.mu}')
    if not is_psd(res.P_predicted):
        raise FilterError(f'P(sigma(t)) lost positive semi-definiteness at mu = {res.mu}')
    why, trace = health(res.x_predicted, res.P_predicted, limit)
    if why:
        raise StateLimitError(why)
    return trace
