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
Health of a filter state and of a step: finite, bounded and positive semi-definite.

    healthy (x, P):  x, P finite,  max_i |x_i| <= state_limit,  trace P <= state_limit^2
    sound step:      P(t|t) and P(sigma(t)) PSD, and the predictor healthy (the filter
                     itself refuses a step with a non-finite estimate and symmetrises P)
"""

import math

import numpy as np

from tskf_ros.core.matrices import FilterError, is_psd, psd_stack
from tskf_ros.core.timescale_kalman import StepResult
from tskf_ros.owc.session.outcome import FloatArray


class StateLimitError(FilterError):
    """A step whose predictor is finite but beyond state_limit: absurd."""


def finite(*arrays: FloatArray) -> bool:
    """Tell whether all entries are finite; on plain floats for the few of a small state."""
    for a in arrays:
        if a.size > 16:
            if not np.isfinite(a).all():
                return False
        elif not all(map(math.isfinite, a.ravel().tolist())):
            return False
    return True


def beyond(largest: float, trace: float, limit: float) -> str:
    """Return why a state with max_i |x_i| = largest and trace P = trace is absurd, or ''."""
    if largest > limit:
        return f'|x| = {largest:.3g} > state_limit = {limit:g}'
    if not trace <= limit * limit:
        return (f'sqrt(trace P) = {math.sqrt(max(trace, 0.0)):.3g} > state_limit = '
                f'{limit:g}')
    return ''


def _largest(x: FloatArray) -> float:
    """Return max_i |x_i| (0 for an empty x), on plain floats."""
    return max(map(abs, x.tolist())) if x.size else 0.0


def _trace(P: FloatArray) -> float:
    """Return trace P, on plain floats up to 2 x 2 (numpy's reductions cost more there)."""
    return P.trace().item() if P.shape[0] > 2 else sum(P.diagonal().tolist())


def unhealthy(x: FloatArray, P: FloatArray, limit: float) -> str:
    """Return why (x, P) is absurd (non-finite, or beyond limit), or '' if it is not."""
    if not finite(x, P):
        return 'a non-finite state or covariance'
    return beyond(_largest(x), _trace(P), limit)


def checked(res: StepResult, limit: float) -> float:
    """
    Return trace P(sigma(t)) of a sound step; raise FilterError if it is not sound.

    Checked here is what the filter does not check itself (see the module docstring); a
    predictor beyond the limit raises StateLimitError.  One state entry is tested on
    plain floats.
    """
    x_p, P_p = res.x_predicted, res.P_predicted
    if not is_psd(res.P_corrected):
        raise FilterError(f'P(t|t) lost positive semi-definiteness at mu = {res.mu}')
    if not is_psd(P_p):
        raise FilterError(f'P(sigma(t)) lost positive semi-definiteness at mu = {res.mu}')
    if x_p.size == 1:
        largest, trace = abs(x_p.item()), P_p.item()
    else:
        largest, trace = _largest(x_p), _trace(P_p)
    why = beyond(largest, trace, limit)
    if why:
        raise StateLimitError(why)
    return trace


def sound_steps(P_corrected: FloatArray, x_predicted: FloatArray, P_predicted: FloatArray,
                limit: float) -> tuple[int, FloatArray]:
    """
    Return how many steps of a run, from the first, `checked` keeps, and their trace P(sigma).

    The same tests as `checked`, on the run's stacks at once: P(t|t) and P(sigma(t)) PSD
    (`psd_stack`), max_i |x_i| <= limit and trace P(sigma(t)) <= limit^2 (`beyond`).
    """
    traces = np.trace(P_predicted, axis1=1, axis2=2)
    largest = np.abs(x_predicted).max(axis=1) if x_predicted.shape[1] else np.zeros(len(traces))
    with np.errstate(over='ignore'):
        sound = (psd_stack(P_corrected) & psd_stack(P_predicted) & ~(largest > limit)
                 & (traces <= limit * limit))
    count = len(sound) if sound.all() else int(np.argmin(sound))
    return count, traces[:count]
