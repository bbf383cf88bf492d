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
The linear quadratic regulator on a time scale (Bohner & Wintz 2013, Section 2, eq. (4)-(8)).

System x^Delta = A x + B u on a time scale with graininess mu, cost (4)

    J = 1/2 x(t_f)^T F x(t_f) + 1/2 int_{t_0}^{t_f} (x^T Q x + u^T R u)(tau) Delta tau,

sweep condition (6) lambda = S x, Riccati equation (7) with S(t_f) = F,

    -S^Delta = A^T S^sigma + (I + mu A^T) S^sigma A
               - (I + mu A^T) S^sigma B (R + mu B^T S^sigma B)^-1 B^T S^sigma (I + mu A) + Q,

and, where R + mu B^T S^sigma B is invertible (Theorem 2.17), u = -L x with gain (8)

    L = (R + mu B^T S^sigma B)^-1 B^T S^sigma (I + mu A).

At a right-scattered point S = S^sigma - mu S^Delta (Theorem 2.5d), which expands to the
Riccati difference equation of x_{k+1} = (I + mu A) x_k + mu B u_k with stage cost
mu (x^T Q x + u^T R u); at mu = 0, (7) is the continuous Riccati equation
-S' = A^T S + S A - S B R^-1 B^T S + Q, integrated backward with scipy.  The optimal
cost is J = 1/2 x(t_0)^T S(t_0) x(t_0).  Derivations and choices: doc/design/lqr.md.
"""

from dataclasses import dataclass, field
import math
from typing import Callable, Iterator, NamedTuple, Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.matrices import as_matrix, check_covariance, FilterError, is_invertible

Matrix = NDArray[np.float64]

__all__ = ['LQRError', 'LQRGains', 'NotInvertibleError', 'Stationary', 'TimeScaleLQR']

# stationary solutions kept per regulator, keyed by mu
STATIONARY_CACHE_SIZE = 64


class LQRError(FilterError):
    """Bad model, weight or time scale given to the regulator."""


class NotInvertibleError(LQRError):
    """R + mu B^T S^sigma B is singular at some point: Theorem 2.17 gives no gain there."""


@dataclass(frozen=True)
class LQRGains:
    """
    The backward sweep over t_0 < ... < t_K = t_f; unpacks as (S, L).

    S[k] = S(t_k) for k = 0..K, L[k] = the gain (8) at t_k for k = 0..K-1, and for every
    dense stretch k (a right-dense [t_k, t_{k+1}]) stretches[k](s) = S(t_k + s),
    s in [0, mu_k], scipy's interpolant of the integrated Riccati equation.
    """

    S: Matrix
    L: Matrix
    stretches: dict[int, Callable[[float], Matrix]] = field(default_factory=dict)

    def __iter__(self) -> Iterator[Matrix]:
        """Yield S and L, so that `S, L = lqr.gains(mu)`."""
        return iter((self.S, self.L))


class Stationary(NamedTuple):
    """The constant-graininess limit of the sweep: S = S^sigma solves (7); L from (8)."""

    S: Matrix
    L: Matrix


def _symmetric(M: Matrix) -> Matrix:
    return M / 2 + M.T / 2


class TimeScaleLQR:
    """
    The regulator of Bohner & Wintz Section 2 on a given graininess sequence.

    `gains(mu, dense)` sweeps (7) backward from S(t_f) = F over the points
    t_{k+1} = t_k + mu_k; `stationary(mu)` is the infinite-horizon solution at a
    constant graininess (DARE of the discrete equivalent, or the CARE at mu = 0).
    Q, F must be symmetric positive semi-definite; R symmetric positive semi-definite
    (Theorem 2.17 only needs R + mu B^T S^sigma B invertible, which the sweep checks at
    each point; a dense stretch needs R positive definite).
    """

    def __init__(self, A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike,
                 F: Optional[ArrayLike] = None) -> None:
        try:
            A_ = as_matrix(A, 'A')
            n = A_.shape[0]
            if A_.shape != (n, n):
                raise LQRError(f'A must be square, got shape {A_.shape}')
            B_ = as_matrix(B, 'B', column=True)
            if B_.shape[0] != n:
                raise LQRError(f'B must have {n} rows to match A, got shape {B_.shape}')
            m = B_.shape[1]
            Q_ = check_covariance(as_matrix(Q, 'Q'), 'Q')
            R_ = check_covariance(as_matrix(R, 'R'), 'R')
            F_ = np.zeros((n, n)) if F is None else check_covariance(as_matrix(F, 'F'), 'F')
        except LQRError:
            raise
        except FilterError as exc:
            raise LQRError(str(exc)) from None
        for name, M, shape in (('Q', Q_, (n, n)), ('R', R_, (m, m)), ('F', F_, (n, n))):
            if M.shape != shape:
                raise LQRError(f'{name} must have shape {shape}, got {M.shape}')
        self._A, self._B, self._Q, self._R, self._F = A_, B_, Q_, R_, F_
        self._cache: dict[float, Stationary] = {}

    A = property(lambda self: self._A, doc='The system matrix A (read-only).')
    B = property(lambda self: self._B, doc='The input matrix B (read-only).')
    Q = property(lambda self: self._Q, doc='The state weight Q of (4) (read-only).')
    R = property(lambda self: self._R, doc='The input weight R of (4) (read-only).')
    F = property(lambda self: self._F, doc='The terminal weight F = S(t_f) (read-only).')

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        """Input dimension."""
        return int(self.B.shape[1])

    def gain(self, S_sigma: Matrix, mu: float) -> Matrix:
        """Return L of (8) at a point of graininess mu, given S^sigma there."""
        A, B, R = self.A, self.B, self.R
        # Theorem 2.17: R + mu B^T S^sigma B must be invertible
        M = R + mu * (B.T @ S_sigma @ B)
        if not is_invertible(M):
            raise NotInvertibleError(
                f'R + mu B^T S^sigma B is singular at mu = {mu:g}: Theorem 2.17 gives no '
                'gain there (make R positive definite, or F weigh what B moves)')
        # (8): L = (R + mu B^T S^sigma B)^-1 B^T S^sigma (I + mu A)
        return np.linalg.solve(M, B.T @ S_sigma @ (np.eye(self.n) + mu * A))

    def step(self, S_sigma: Matrix, mu: float) -> tuple[Matrix, Matrix]:
        """Return (S(t), L(t)) at a right-scattered t of graininess mu > 0 from S(sigma(t))."""
        if not (mu > 0 and math.isfinite(mu)):
            raise LQRError(f'step needs a finite mu > 0 (a right-scattered point), got {mu}; '
                           'a dense stretch is integrated (gains with dense=...)')
        A, B, Q = self.A, self.B, self.Q
        L = self.gain(S_sigma, mu)
        Phi_t = np.eye(self.n) + mu * A.T
        # (7): -S^Delta = A^T S^sigma + (I + mu A^T) S^sigma A - (I + mu A^T) S^sigma B L + Q
        minus_dS = A.T @ S_sigma + Phi_t @ S_sigma @ A - Phi_t @ S_sigma @ B @ L + Q
        # Theorem 2.5d: S = S^sigma - mu S^Delta
        S = S_sigma + mu * minus_dS
        return _symmetric(S), L

    def integrate(self, S_end: Matrix, duration: float, *, rtol: float = 1e-10,
                  atol: float = 1e-12) -> tuple[Matrix, Callable[[float], Matrix]]:
        """
        Solve (7) at mu = 0 backward over a dense stretch of `duration`.

        Return S at the start and s -> S(start + s), s in [0, duration] (scipy's DOP853).
        """
        A, B, Q, R = self.A, self.B, self.Q, self.R
        if not (math.isfinite(duration) and duration > 0):
            raise LQRError(f'a dense stretch needs a finite length > 0, got {duration}')
        if not np.all(np.linalg.eigvalsh(R) > 0):
            raise LQRError('a dense stretch needs R positive definite (the continuous '
                           'Riccati equation has R^-1)')
        n = self.n
        BRinvBt = B @ np.linalg.solve(R, B.T)

        def rhs(_: float, s: NDArray[np.float64]) -> NDArray[np.float64]:
            S = s.reshape(n, n)
            # (7) at mu = 0: -S' = A^T S + S A - S B R^-1 B^T S + Q
            dS = -(A.T @ S + S @ A - S @ BRinvBt @ S + Q)
            return _symmetric(dS).reshape(-1)

        import scipy.integrate    # noqa: I900 - here: 0.3 s a node never needs
        sol = scipy.integrate.solve_ivp(rhs, (duration, 0.0), S_end.reshape(-1),
                                        method='DOP853', rtol=rtol, atol=atol,
                                        dense_output=True)
        if not sol.success:
            raise LQRError(f'the Riccati integration over a dense stretch failed: {sol.message}')
        interpolant = sol.sol

        def inside(s: float) -> Matrix:
            return _symmetric(np.asarray(interpolant(s), dtype=float).reshape(n, n))

        return _symmetric(sol.y[:, -1].reshape(n, n)), inside

    def gains(self, mu: ArrayLike, dense: Optional[ArrayLike] = None, *,
              rtol: float = 1e-10, atol: float = 1e-12) -> LQRGains:
        """
        Sweep (7) backward from S(t_f) = F over t_{k+1} = t_k + mu_k, k = 0..K-1.

        mu_k > 0 is the graininess of a right-scattered t_k.  dense (K booleans, default
        none) marks right-dense stretches: where dense[k], [t_k, t_{k+1}] is an interval
        of the time scale (graininess 0) of length mu_k, over which (7) is integrated as
        the continuous Riccati equation, and L[k] = R^-1 B^T S(t_k) (gain (8) at mu = 0).
        This is how `tskf_ros.core.time_scales.TimeScale` marks its dense stretches:
        `gains(ts.mu()[:-1], ts.dense)`.
        """
        mus, flags = self._check_time_scale(mu, dense)
        K, n, m = mus.size, self.n, self.m
        S = np.empty((K + 1, n, n))
        L = np.empty((K, m, n))
        stretches: dict[int, Callable[[float], Matrix]] = {}
        S[K] = self.F
        for k in range(K - 1, -1, -1):
            if flags[k]:
                S[k], stretches[k] = self.integrate(S[k + 1], float(mus[k]), rtol=rtol, atol=atol)
                # at a right-dense point S^sigma = S and mu = 0
                L[k] = self.gain(S[k], 0.0)
            else:
                try:
                    S[k], L[k] = self.step(S[k + 1], float(mus[k]))
                except NotInvertibleError as exc:
                    raise NotInvertibleError(f'at t_{k} (of {K} steps): {exc}') from None
            if not np.all(np.isfinite(S[k])):
                raise LQRError(f'S overflowed at t_{k} (mu = {mus[k]:g}); the sweep is refused')
        return LQRGains(S, L, stretches)

    def stationary(self, mu: float) -> Stationary:
        """
        Return the limit of the sweep at a constant graininess mu (cached per mu).

        mu > 0: S solves the DARE of the discrete equivalent, a = I + mu A, b = mu B,
        q = mu Q, r = mu R (scipy.linalg.solve_discrete_are); mu = 0: the CARE
        (scipy.linalg.solve_continuous_are).  L is the gain (8) at S^sigma = S.
        """
        mu = self._check_mu(mu)
        cache = self._cache
        if mu in cache:
            return cache[mu]
        A, B, Q, R = self.A, self.B, self.Q, self.R
        n = self.n
        import scipy.linalg    # noqa: I900 - here: 0.4 s a node may not need
        try:
            if mu > 0:
                S = scipy.linalg.solve_discrete_are(np.eye(n) + mu * A, mu * B, mu * Q, mu * R)
            else:
                S = scipy.linalg.solve_continuous_are(A, B, Q, R)
        except (np.linalg.LinAlgError, ValueError) as exc:
            reason = ' '.join(str(exc).split())
            raise LQRError(f'no stationary solution at mu = {mu:g} ((A, B) not stabilizable, '
                           f'or a mode on the stability boundary unweighted): {reason}') from None
        S = _symmetric(S)
        result = Stationary(S, self.gain(S, mu))
        if len(cache) >= STATIONARY_CACHE_SIZE:
            del cache[next(iter(cache))]
        cache[mu] = result
        return result

    @staticmethod
    def _check_mu(mu: float) -> float:
        try:
            value = float(mu)
        except (TypeError, ValueError):
            raise LQRError(f'mu must be a number, got {mu!r}') from None
        if not math.isfinite(value) or value < 0:
            raise LQRError(f'mu must be finite and >= 0, got {value}')
        return value

    @staticmethod
    def _check_time_scale(mu: ArrayLike, dense: Optional[ArrayLike]
                          ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        try:
            mus = np.array(mu, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise LQRError(f'mu must be a sequence of numbers, got {mu!r}') from None
        if mus.size == 0:
            raise LQRError('mu is empty: the time scale needs at least one step')
        flags = (np.zeros(mus.size, dtype=bool) if dense is None
                 else np.array(dense, dtype=bool).reshape(-1))
        if flags.shape != mus.shape:
            raise LQRError(f'dense needs one flag per step ({mus.size}), got {flags.size}')
        bad = ~np.isfinite(mus) | (mus < 0)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise LQRError(f'mu must be finite and >= 0, got mu[{k}] = {mus[k]}')
        zero = mus == 0
        if zero.any():
            k = int(np.flatnonzero(zero)[0])
            what = 'a dense stretch needs its length > 0' if flags[k] else (
                'mu = 0 is a right-dense point: give the stretch length as mu[k] with '
                'dense[k] = True')
            raise LQRError(f'mu[{k}] = 0: {what}')
        return mus, flags
