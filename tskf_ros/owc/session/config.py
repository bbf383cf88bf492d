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
The estimator session's parameters: the model, the jump form and the input bounds.

A config is validated by what it does: x0, P0 healthy, and one trial step of
mu = period from (x0, P0) with y = C x0 + D healthy (tskf_ros.owc.session.health).
"""

from dataclasses import dataclass
from math import isqrt
from typing import Sequence

import numpy as np

from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.timescale_kalman import FilterError, TimeScaleKalmanFilter, TRANSITIONS
from tskf_ros.owc.session.health import unhealthy
from tskf_ros.owc.session.outcome import FloatArray


class ConfigError(ValueError):
    """Estimator parameters that cannot be used; the message says why."""


def _flat(values: Sequence[float], name: str) -> FloatArray:
    v = np.asarray(list(values), dtype=float).reshape(-1)
    if not np.all(np.isfinite(v)):
        raise ConfigError(f'{name} has non-finite entries')
    return v


def model_from_flat(*, A: Sequence[float], C: Sequence[float], Q: Sequence[float],
                    R: Sequence[float], x0: Sequence[float], P0: Sequence[float],
                    G: Sequence[float] = (), B: Sequence[float] = (),
                    D: Sequence[float] = (), name: str = 'model',
                    state_names: Sequence[str] = ()) -> LinearModel:
    """
    Build a LinearModel from row-major flat lists, inferring the shapes (ROS parameters).

    A is n x n, C is p x n, G is n x r (empty: I), Q is r x r, R is p x p, B is n x m
    (empty: none), D has p entries (empty: 0), x0 has n and P0 n x n entries.
    """
    a = _flat(A, 'A')
    n = isqrt(a.size)
    if n == 0 or n * n != a.size:
        raise ConfigError(f'A must have n^2 entries for some n >= 1, got {a.size}')
    c = _flat(C, 'C')
    if c.size == 0 or c.size % n:
        raise ConfigError(f'C must have p * {n} entries (p x n, row-major), got {c.size}')
    p = c.size // n
    g = _flat(G, 'G')
    if g.size and g.size % n:
        raise ConfigError(f'G must have {n} * r entries (n x r), got {g.size}')
    r = g.size // n if g.size else n
    arrays = {'Q': (_flat(Q, 'Q'), r * r), 'R': (_flat(R, 'R'), p * p),
              'x0': (_flat(x0, 'x0'), n), 'P0': (_flat(P0, 'P0'), n * n)}
    for key, (v, size) in arrays.items():
        if v.size != size:
            raise ConfigError(f'{key} must have {size} entries to match A and C, got {v.size}')
    b = _flat(B, 'B')
    if b.size % n:
        raise ConfigError(f'B must have {n} * m entries (n x m), got {b.size}')
    d = _flat(D, 'D')
    if d.size not in (0, p):
        raise ConfigError(f'D must have {p} entries (or none), got {d.size}')
    names = tuple(state_names) or tuple(f'x{i}' for i in range(n))
    if len(names) != n:
        raise ConfigError(f'state_names must have {n} names, got {len(names)}')
    return LinearModel(name, A=a.reshape(n, n), C=c.reshape(p, n),
                       Q=arrays['Q'][0].reshape(r, r), R=arrays['R'][0].reshape(p, p),
                       x0=arrays['x0'][0], P0=arrays['P0'][0].reshape(n, n),
                       G=g.reshape(n, r) if g.size else None,
                       B=b.reshape(n, -1) if b.size else None,
                       D=d if d.size else None, state_names=names)


# the bounds that must be finite and >= 0
_NON_NEGATIVE = ('period', 'dense_fraction', 'jump_factor', 'max_gap', 'history_window',
                 'max_jump', 'max_backward', 'max_future', 'gate', 'state_limit',
                 'expected_rate', 'rate_tolerance')


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything the session needs: the model, the jump form and the input bounds (s)."""

    model: LinearModel
    transition: str = 'euler'
    period: float = 1.0             # nominal sample period: classifies dense/discrete/jump
    dense_fraction: float = 0.5     # dt < dense_fraction * period: a dense stretch
    jump_factor: float = 1.5        # dt > jump_factor * period: a gap, J = dt
    max_gap: float = 5.0            # a gap longer than this raises diagnostics to WARN
    history_window: float = 10.0    # how far back a late sample may still be inserted
    history_size: int = 1000        # points kept for rewinding
    max_jump: float = 60.0          # a forward jump beyond this re-initialises
    max_backward: float = 30.0      # a backward jump beyond this re-initialises
    max_future: float = 0.0         # stamp ahead of the receiver clock by more: rejected (0 off)
    nonpositive_is_gap: bool = True  # a reading <= 0 is an interruption (a power, Cai IV-C)
    gate: float = 10.0              # Mahalanobis distance of a rejected innovation (0: off)
    gate_patience: int = 5          # consecutive gated samples before a re-initialisation
    use_message_variance: bool = False  # R_d = the sample's own variance when it is > 0
    measurement_range: tuple[float, ...] = ()  # (lo, hi) of a physical reading; (): any
    state_limit: float = 1e9        # |x_i| or sqrt(trace P) beyond this: re-initialise
    expected_rate: float = 0.0      # Hz of the input (FrequencyStatus); 0: 1 / period
    rate_tolerance: float = 0.5     # FrequencyStatus's tolerance around expected_rate

    def __post_init__(self) -> None:
        """Check the bounds and that the model makes a filter; raise ConfigError if not."""
        if self.transition not in TRANSITIONS:
            raise ConfigError(f'transition must be one of {TRANSITIONS}, '
                              f'got {self.transition!r}')
        for name in _NON_NEGATIVE:
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ConfigError(f'{name} must be finite and >= 0, got {value}')
        if not self.period > 0:
            raise ConfigError(f'period must be > 0, got {self.period}')
        if self.gate_patience < 0:
            raise ConfigError(f'gate_patience must be >= 0, got {self.gate_patience}')
        if self.history_size < 2:
            raise ConfigError(f'history_size must be >= 2, got {self.history_size}')
        if not self.max_jump > 0:
            raise ConfigError(f'max_jump must be > 0, got {self.max_jump}')
        if self.max_backward < self.history_window:
            raise ConfigError(f'max_backward ({self.max_backward} s) must be at least '
                              f'history_window ({self.history_window} s)')
        if not self.state_limit > 0:
            raise ConfigError(f'state_limit must be > 0, got {self.state_limit}')
        if self.measurement_range:
            r = tuple(self.measurement_range)
            if len(r) != 2 or not all(np.isfinite(r)) or not r[0] < r[1]:
                raise ConfigError('measurement_range must be empty or [lo, hi] with finite '
                                  f'lo < hi, got {list(r)}')
        try:
            self.model.make_filter(self.transition)
        except FilterError as exc:
            raise ConfigError(str(exc)) from None
        # a model that is not regressive at mu = period is refused step by step, not here
        self._trial(self.model.make_filter(self.transition, allow_nonregressive=True))

    def _trial(self, kf: TimeScaleKalmanFilter) -> None:
        """
        Refuse a model that is absurd at x0, P0 or after one nominal step from there.

        Longer jumps are not tried: an unstable model may legitimately blow up over
        max_jump (e^60 for Cai's A = 1 with the exact transition); at run time such a
        step re-initialises the filter instead ('state_health').
        """
        x0, P0 = kf.x, kf.P
        why = unhealthy(x0, P0, self.state_limit)
        if why:
            raise ConfigError(f'the initial state is absurd: {why}')
        mu = self.period
        try:
            with np.errstate(all='ignore'):
                res = kf.step(mu, kf.C @ x0 + kf.D, np.zeros(kf.B.shape[1]))
        except (FilterError, ArithmeticError, np.linalg.LinAlgError) as exc:
            raise ConfigError(f'a step of mu = {mu:g} s from x0, P0 fails: {exc}') from None
        why = unhealthy(res.x_predicted, res.P_predicted, self.state_limit)
        if why:
            raise ConfigError(f'a step of mu = period = {mu:g} s from x0, P0 gives {why}')
