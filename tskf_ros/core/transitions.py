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
The jump of the time-scale filter over one graininess mu: F, Q_d and B_d.

Euler (Bohner & Wintz 2013, Table 3): F = I + mu A, Q_d = mu G Q G^T, B_d = mu B.
Exact (a continuous plant sampled at irregular instants): F = e^{A mu}, Q_d = Van Loan's
integral (Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 1978),
both as Taylor series in mu whose coefficients depend on the model only (made once per
filter), B_d = int_0^mu e^{A s} ds B.  The transitions of many mu (the distinct
graininesses of a run of jittered stamps) are made in one compiled call; a single mu is a
stack of one.
"""

import math
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

# the filter's matrix product: loops for small matrices, BLAS for large ones
from tskf_ros.core.jit import kernel
from tskf_ros.core.kalman import _mm, update_predict

Matrix = NDArray[np.float64]
Stack = NDArray[np.float64]
TRANSITIONS = ('euler', 'exact')
# transitions kept per filter, keyed by mu (a stream at a fixed rate reuses a few)
CACHE_SIZE = 64
# the Taylor series of e^X for ||X|| <= 1/2 (the A block's norm): N terms, the fewest with
# ||X||^N / (N + 1)! <= 2^-54, a bound on the first term left out relative to the leading
# I (or, in the off-diagonal block, to GQG^T mu); at ||X|| = 1/2 that is 14 terms
_TAYLOR_TERMS = 14
_TAYLOR_TOLERANCE = 2.0 ** -54
# Hadamard's test of I + mu A (Definition 2.12): |det F| > _RTOL prod_i |row_i of F|
_RTOL = 1e-12

_jit = kernel


@_jit
def _taylor_terms(norm: float) -> int:
    """Return the fewest terms N with norm^N / (N + 1)! <= _TAYLOR_TOLERANCE (norm <= 1/2)."""
    bound = 1.0                         # norm^N / (N + 1)! at N = 0
    for N in range(1, _TAYLOR_TERMS):
        bound *= norm / (N + 1)
        if bound <= _TAYLOR_TOLERANCE:
            return N
    return _TAYLOR_TERMS


@_jit
def _expm_taylor(X: Matrix, norm: float, V: Matrix) -> Matrix:
    """
    Return e^X V for ||X|| <= norm <= 1/2 by the Taylor series of e^X, in Horner's form.

    e^X = I + X (I + X/2 (I + X/3 (... (I + X/N)))) (Moler & Van Loan, "Nineteen dubious
    ways to compute the exponential of a matrix", SIAM Review 2003, method 3; the scaling
    and squaring around it is the caller's), with N = _taylor_terms(norm), times V from
    the innermost term out: S = V + X S / k, so that columns of e^X (V = some columns of
    I) cost their share of the products only.
    """
    E = V.copy()
    for k in range(_taylor_terms(norm), 0, -1):
        # E = V + X E / k, in place on the product (one new array a term)
        E = _mm(X, E)
        E /= k
        E += V
    return E


@_jit
def _norm(A: Matrix) -> float:
    """Return max(||A||_1, ||A||_inf)."""
    return max(np.abs(A).sum(axis=0).max(), np.abs(A).sum(axis=1).max())


@_jit
def _halvings(norm: float, mu: float) -> int:
    """Return k with norm mu / 2^k <= 1/2 (norm = _norm(A)): the halvings of mu."""
    if not 2.0 * norm * mu > 1.0:
        return 0
    # in logarithms: norm * mu may overflow where mu / 2^k does not
    return int(np.ceil(np.log2(2.0 * norm) + np.log2(mu)))


@_jit
def van_loan_series(A: Matrix, GQGt: Matrix) -> tuple[Stack, Stack, float]:
    """
    Return the Taylor coefficients of F(h) and Q_d(h) in s = nu h, and ||A|| (`_norm`).

    F(h) = e^{A h} = sum_k s^k F_k,  F_k = (A / nu)^k / k!
    Q_d(h) = int_0^h F(r) GQG^T F(r)^T dr = sum_k s^k D_k, the series of the solution of
    Q_d' = A Q_d + Q_d A^T + GQG^T, Q_d(0) = 0 (Van Loan 1978, eq. 1.2):
    D_1 = GQG^T / nu,  k D_k = (A / nu) D_{k-1} + D_{k-1} (A / nu)^T
    with nu = ||A|| (1 for A = 0), k = 0 .. _TAYLOR_TERMS.  They depend on the model only:
    a filter makes them once and sums them for every mu (`van_loan_from`), n^2 work per
    term instead of the products of the 2n x 2n block exponential.
    """
    n = A.shape[0]
    norm = _norm(A)
    nu = norm if norm > 0.0 else 1.0
    X = np.ascontiguousarray(A / nu)
    Fk = np.zeros((_TAYLOR_TERMS + 1, n, n))
    Dk = np.zeros((_TAYLOR_TERMS + 1, n, n))
    for i in range(n):
        Fk[0, i, i] = 1.0
    Dk[1] = GQGt / nu
    for k in range(1, _TAYLOR_TERMS + 1):
        # F_k = X F_{k-1} / k
        Fk[k] = _mm(X, Fk[k - 1]) / k
        if k > 1:
            # D_k = (X D_{k-1} + D_{k-1} X^T) / k, D_{k-1} symmetric: (X D + (X D)^T) / k
            XD = _mm(X, Dk[k - 1])
            Dk[k] = (XD + XD.T) / k
    return Fk, Dk, norm


@_jit
def van_loan_from(Fk: Stack, Dk: Stack, norm: float, mu: float) -> tuple[Matrix, Matrix]:
    """
    Return the exact (F, Q_d) over mu from `van_loan_series`'s coefficients.

    The series are summed over h = mu / 2^k with 2 ||A|| h <= 1/2, in Horner's form, to
    N = _taylor_terms(2 ||A|| h) terms (the first term of Q_d's series left out is at most
    (2 ||A|| h)^N / (N + 1)! of GQG^T h), and doubled k times:
    F(2h) = F(h)^2, Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T (the one-shot block exponential
    holds e^{-A mu}, which for a stable A and a long mu, 60 s of a spring-mass system, is
    so large that F and Q_d lose every digit).
    """
    k = _halvings(2.0 * norm, mu)
    h = math.ldexp(mu, -k)
    N = _taylor_terms(2.0 * norm * h)
    s = h * norm if norm > 0.0 else h
    # F = F_0 + s (F_1 + s (... + s F_N)),  Q_d = s (D_1 + s (D_2 + ... + s D_N))
    F = Fk[N].copy()
    Qd = Dk[N].copy()
    for j in range(N - 1, 0, -1):
        F *= s
        F += Fk[j]
        Qd *= s
        Qd += Dk[j]
    F *= s
    F += Fk[0]
    Qd *= s
    for _ in range(k):
        # Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T
        Qd = Qd + _mm(_mm(F, Qd), np.ascontiguousarray(F.T))
        # F(2h) = F(h)^2
        F = _mm(F, F)
    return F, Qd / 2 + Qd.T / 2


@_jit
def van_loan(A: Matrix, GQGt: Matrix, mu: float) -> tuple[Matrix, Matrix]:
    """
    Return the exact (F, Q_d) of x' = A x + G w over mu.

    F = e^{A mu}, Q_d = int_0^mu F(s) GQG^T F(s)^T ds (Van Loan 1978), summed as Taylor
    series in mu (`van_loan_series`, `van_loan_from`).
    """
    Fk, Dk, norm = van_loan_series(A, GQGt)
    return van_loan_from(Fk, Dk, norm, mu)


@_jit
def exact_input_matrix(A: Matrix, B: Matrix, mu: float) -> Matrix:
    """
    Return B_d = int_0^mu e^{A s} ds B.

    expm([[A, B], [0, 0]] h) = [[F(h), B_d(h)], [0, I]] over h = mu / 2^k, doubled k times:
    B_d(2h) = B_d(h) + F(h) B_d(h), F(2h) = F(h)^2.
    """
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    norm = _norm(A)
    k = _halvings(norm, mu)
    h = math.ldexp(mu, -k)
    E = _expm_taylor(M * h, min(norm * h, 0.5), np.eye(n + m))
    F = np.ascontiguousarray(E[:n, :n])
    Bd = np.ascontiguousarray(E[:n, n:])
    for _ in range(k):
        # B_d(2h) = B_d(h) + F(h) B_d(h)
        Bd = Bd + _mm(F, Bd)
        # F(2h) = F(h)^2
        F = _mm(F, F)
    return Bd


@_jit
def van_loan_stack_from(Fk: Stack, Dk: Stack, norm: float, mus: NDArray[np.float64]
                        ) -> tuple[Stack, Stack]:
    """Return `van_loan_from` over each mu of mus, stacked (K, n, n)."""
    n, K = Fk.shape[1], mus.shape[0]
    F, Qd = np.empty((K, n, n)), np.empty((K, n, n))
    for i in range(K):
        F[i], Qd[i] = van_loan_from(Fk, Dk, norm, mus[i])
    return F, Qd


@_jit
def van_loan_stack(A: Matrix, GQGt: Matrix, mus: NDArray[np.float64]) -> tuple[Stack, Stack]:
    """Return `van_loan` over each mu of mus, stacked (K, n, n): the series made once."""
    Fk, Dk, norm = van_loan_series(A, GQGt)
    return van_loan_stack_from(Fk, Dk, norm, mus)


@_jit
def exact_input_stack(A: Matrix, B: Matrix, mus: NDArray[np.float64]) -> Stack:
    """Return `exact_input_matrix` over each mu of mus, stacked (K, n, m)."""
    out = np.empty((mus.shape[0],) + B.shape)
    for i in range(mus.shape[0]):
        out[i] = exact_input_matrix(A, B, mus[i])
    return out


@_jit
def _invertible(F: Matrix) -> bool:
    """
    Tell whether F is numerically invertible.

    |det F| > _RTOL prod_i |row_i| (Hadamard's bound: |det F| <= prod_i |row_i|, with
    equality for orthogonal rows; the test is scale-free).
    """
    n = F.shape[0]
    if n == 1:
        return F[0, 0] != 0.0
    if n == 2:
        det = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    else:
        det = np.linalg.det(F)
    bound = 1.0
    for i in range(n):
        bound *= np.sqrt((F[i] * F[i]).sum())
    return bound > 0.0 and abs(det) > _RTOL * bound


@_jit
def euler(A: Matrix, GQGt: Matrix, B: Matrix, mu: float
          ) -> tuple[Matrix, Matrix, Matrix, bool]:
    """Return the Euler jump over mu: (F, Q_d, B_d, whether F is invertible)."""
    # x(sigma) = (I + mu A) x + mu B u + mu G w, Var(mu G w) = mu GQG^T
    F = np.eye(A.shape[0]) + mu * A
    Qd = mu * GQGt
    Bd = mu * B
    # Definition 2.12: I + mu A invertible
    return F, Qd, Bd, _invertible(F)


@_jit
def euler_stack(A: Matrix, GQGt: Matrix, B: Matrix, mus: NDArray[np.float64]
                ) -> tuple[Stack, Stack, Stack, NDArray[np.bool_]]:
    """Return `euler` over each mu of mus, stacked (K, ...)."""
    n, K = A.shape[0], mus.shape[0]
    F, Qd = np.empty((K, n, n)), np.empty((K, n, n))
    Bd, regressive = np.empty((K,) + B.shape), np.empty(K, dtype=np.bool_)
    for i in range(K):
        F[i], Qd[i], Bd[i], regressive[i] = euler(A, GQGt, B, mus[i])
    return F, Qd, Bd, regressive


@_jit
def noise_over(R: Matrix, mu: float) -> Matrix:
    """R_d = R / mu: white noise of intensity R seen through a point of measure mu."""
    return R / mu


@_jit
def jump_update_predict(x: NDArray[np.float64], P: Matrix, z: NDArray[np.float64], H: Matrix,
                        R: Matrix, d: NDArray[np.float64], A: Matrix, GQGt: Matrix,
                        B: Matrix, Fk: Stack, Dk: Stack, norm: float, mu: float, exact: bool
                        ) -> tuple[tuple[NDArray[np.float64], Matrix, NDArray[np.float64],
                                         Matrix, NDArray[np.float64], Matrix, int], bool]:
    """
    Return the step over mu in one compiled call, without an input (B u = 0).

    kalman.update_predict with R_d = R / mu and the jump's F, Q_d (Euler, or exact:
    `euler` / `van_loan_from` over the model's series Fk, Dk, norm), and whether I + mu A
    is invertible: on jittered stamps every mu is new, and building its jump apart costs
    a call and a cache entry more.
    """
    if exact:
        F, Qd = van_loan_from(Fk, Dk, norm, mu)
        regressive = True
    else:
        F, Qd, _, regressive = euler(A, GQGt, B, mu)
    step = update_predict(x, P, z, H, noise_over(R, mu), d, F, Qd, np.zeros(x.shape[0]))
    return step, regressive


class Transition(NamedTuple):
    """The jump over one graininess mu, and whether I + mu A is invertible (Definition 2.12)."""

    F: Matrix
    Qd: Matrix
    Bd: Matrix
    regressive: bool


class Transitions(NamedTuple):
    """The jumps over the mu of a run, stacked: F, Q_d, B_d (K, ...) and regressive (K,)."""

    F: Stack
    Qd: Stack
    Bd: Stack
    regressive: NDArray[np.bool_]


def transitions(kind: str, A: Matrix, GQGt: Matrix, B: Matrix, mus: NDArray[np.float64],
                *, input_matrix: bool = True,
                series: Optional[tuple[Stack, Stack, float]] = None) -> Transitions:
    """
    Return the jumps over every mu of mus in one compiled call: Euler or the exact plant.

    input_matrix=False leaves B_d at zero for the exact transition (a model without an
    input needs no second exponential); series is `van_loan_series(A, GQGt)` if made.
    """
    mus = np.ascontiguousarray(mus, dtype=float)
    if kind == 'euler':
        return Transitions(*euler_stack(A, GQGt, B, mus))
    F, Qd = van_loan_stack_from(*(series or van_loan_series(A, GQGt)), mus)
    Bd = exact_input_stack(A, B, mus) if input_matrix else np.zeros((mus.size,) + B.shape)
    # e^{A mu} is always invertible
    return Transitions(F, Qd, Bd, np.ones(mus.size, dtype=np.bool_))


def transition(kind: str, A: Matrix, GQGt: Matrix, B: Matrix, mu: float,
               *, input_matrix: bool = True,
               series: Optional[tuple[Stack, Stack, float]] = None) -> Transition:
    """(F, Q_d, B_d) for a jump of mu: the paper's Euler form or the exact sampled plant."""
    if kind == 'euler':
        return Transition(*euler(A, GQGt, B, mu))
    F, Qd = van_loan_from(*(series or van_loan_series(A, GQGt)), mu)
    Bd = exact_input_matrix(A, B, mu) if input_matrix else np.zeros(B.shape)
    # e^{A mu} is always invertible
    return Transition(F, Qd, Bd, True)


class TransitionCache(dict[float, Transition]):
    """The transitions of one model by mu, computed on first use, the last CACHE_SIZE kept."""

    def __init__(self, kind: str, A: Matrix, GQGt: Matrix, B: Matrix, *,
                 input_matrix: bool = True) -> None:
        super().__init__()
        self.kind, self.input_matrix = kind, input_matrix
        self.seen: set[float] = set()       # mu met once, not cached (see `once`)
        self.A, self.GQGt, self.B = (np.ascontiguousarray(M, dtype=float) for M in (A, GQGt, B))
        self._series: Optional[tuple[Stack, Stack, float]] = None

    @property
    def series(self) -> tuple[Stack, Stack, float]:
        """Return `van_loan_series` of the model (exact transition), made on first use."""
        if self._series is None:
            if self.kind == 'exact':
                self._series = van_loan_series(self.A, self.GQGt)
            else:       # Euler sums no series: empty stacks of the kernels' types
                empty = np.empty((0,) + self.A.shape)
                self._series = (empty, empty, 0.0)
        return self._series

    def __missing__(self, mu: float) -> Transition:
        jump = transition(self.kind, self.A, self.GQGt, self.B, mu,
                          input_matrix=self.input_matrix, series=self.series)
        if len(self) >= CACHE_SIZE:
            del self[next(iter(self))]
        self[mu] = jump
        return jump

    def once(self, mu: float) -> bool:
        """
        Tell whether mu is met for the first time (not cached, not met once before).

        A jump is cached from the second time its mu is met: the mu of jittered stamps
        never come back, and building their jumps inside the step (`jump_update_predict`)
        saves a call and a cache entry each.
        """
        if mu in self or mu in self.seen:
            return False
        if len(self.seen) >= CACHE_SIZE:
            self.seen.clear()
        self.seen.add(mu)
        return True

    def step_once(self, x: NDArray[np.float64], P: Matrix, z: NDArray[np.float64], H: Matrix,
                  R: Matrix, d: NDArray[np.float64], mu: float
                  ) -> tuple[tuple[NDArray[np.float64], Matrix, NDArray[np.float64], Matrix,
                                   NDArray[np.float64], Matrix, int], bool]:
        """Return jump_update_predict over mu (no input) and whether I + mu A is invertible."""
        return jump_update_predict(x, P, z, H, R, d, self.A, self.GQGt, self.B, *self.series,
                                   mu, self.kind == 'exact')

    def stack(self, mus: NDArray[np.float64]) -> Transitions:
        """Return the transitions of every mu of mus (a run's distinct values) in one call."""
        return transitions(self.kind, self.A, self.GQGt, self.B, mus,
                           input_matrix=self.input_matrix, series=self.series)


def warm_up() -> None:
    """Compile the transition kernels for float64 arrays, or load them from numba's cache."""
    A, mus = np.eye(2), np.ones(1)
    euler(A, A, A[:, :1], 1.0)
    van_loan(A, A, 1.0)
    exact_input_matrix(A, A[:, :1], 1.0)
    euler_stack(A, A, A[:, :1], mus)
    van_loan_stack(A, A, mus)
    exact_input_stack(A, A[:, :1], mus)
    Fk, Dk, norm = van_loan_series(A, A)
    van_loan_stack_from(Fk, Dk, norm, mus)
    x, z, H = np.zeros(2), np.zeros(1), np.ones((1, 2))
    for exact in (False, True):
        jump_update_predict(x, A, z, H, np.eye(1), z, A, A, A[:, :1], Fk, Dk, norm, 1.0, exact)
