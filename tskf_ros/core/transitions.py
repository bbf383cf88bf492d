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
Exact (a continuous plant sampled at irregular instants): F = e^{A mu}, Q_d by Van Loan's
method (Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 1978),
B_d = int_0^mu e^{A s} ds B.  The transitions of many mu (the distinct graininesses of a run
of jittered stamps) are made in one compiled call; a single mu is a stack of one.
"""

import math
from typing import NamedTuple

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
def van_loan(A: Matrix, GQGt: Matrix, mu: float) -> tuple[Matrix, Matrix]:
    """
    Return the exact (F, Q_d) of x' = A x + G w over mu.

    F = e^{A mu}, Q_d = int_0^mu F(s) GQG^T F(s)^T ds.
    Van Loan (1978): expm([[-A, GQG^T], [0, A^T]] h) = [[., F(h)^-1 Q_d(h)], [0, F(h)^T]],
    taken over h = mu / 2^k small enough for the Taylor series and doubled k times,
    F(2h) = F(h)^2, Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T: the one-shot block exponential
    holds e^{-A mu}, which for a stable A and a long mu (60 s of a spring-mass system) is
    so large that F and Q_d lose every digit (F came out 1e10, Q_d indefinite).  Only the
    right-hand block column of the exponential is used, and only it is summed (half the
    products of the whole 2n x 2n series, the same sums).
    """
    n = A.shape[0]
    norm = _norm(A)
    k = _halvings(norm, mu)
    h = math.ldexp(mu, -k)
    # M h, M = [[-A, GQG^T], [0, A^T]]
    Mh = np.zeros((2 * n, 2 * n))
    for i in range(n):
        for j in range(n):
            Mh[i, j] = -A[i, j] * h
            Mh[i, n + j] = GQGt[i, j] * h
            Mh[n + i, n + j] = A[j, i] * h
    right = np.zeros((2 * n, n))     # the right-hand columns of I
    for i in range(n):
        right[n + i, i] = 1.0
    E = _expm_taylor(Mh, min(norm * h, 0.5), right)
    F = np.ascontiguousarray(E[n:].T)
    Qd = _mm(F, np.ascontiguousarray(E[:n]))
    for _ in range(k):
        # Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T
        Qd = Qd + _mm(_mm(F, Qd), np.ascontiguousarray(F.T))
        # F(2h) = F(h)^2
        F = _mm(F, F)
    return F, Qd / 2 + Qd.T / 2


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
def van_loan_stack(A: Matrix, GQGt: Matrix, mus: NDArray[np.float64]) -> tuple[Stack, Stack]:
    """Return `van_loan` over each mu of mus, stacked (K, n, n)."""
    n, K = A.shape[0], mus.shape[0]
    F, Qd = np.empty((K, n, n)), np.empty((K, n, n))
    for i in range(K):
        F[i], Qd[i] = van_loan(A, GQGt, mus[i])
    return F, Qd


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
                        B: Matrix, mu: float, exact: bool
                        ) -> tuple[tuple[NDArray[np.float64], Matrix, NDArray[np.float64],
                                         Matrix, NDArray[np.float64], Matrix, int], bool]:
    """
    Return the step over mu in one compiled call, without an input (B u = 0).

    kalman.update_predict with R_d = R / mu and the jump's F, Q_d (Euler, or exact:
    `euler` / `van_loan` above), and whether I + mu A is invertible: on jittered stamps
    every mu is new, and building its jump apart costs a call and a cache entry more.
    """
    if exact:
        F, Qd = van_loan(A, GQGt, mu)
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
                *, input_matrix: bool = True) -> Transitions:
    """
    Return the jumps over every mu of mus in one compiled call: Euler or the exact plant.

    input_matrix=False leaves B_d at zero for the exact transition (a model without an
    input needs no second exponential).
    """
    mus = np.ascontiguousarray(mus, dtype=float)
    if kind == 'euler':
        return Transitions(*euler_stack(A, GQGt, B, mus))
    F, Qd = van_loan_stack(A, GQGt, mus)
    Bd = exact_input_stack(A, B, mus) if input_matrix else np.zeros((mus.size,) + B.shape)
    # e^{A mu} is always invertible
    return Transitions(F, Qd, Bd, np.ones(mus.size, dtype=np.bool_))


def transition(kind: str, A: Matrix, GQGt: Matrix, B: Matrix, mu: float,
               *, input_matrix: bool = True) -> Transition:
    """(F, Q_d, B_d) for a jump of mu: the paper's Euler form or the exact sampled plant."""
    if kind == 'euler':
        return Transition(*euler(A, GQGt, B, mu))
    F, Qd = van_loan(A, GQGt, mu)
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

    def __missing__(self, mu: float) -> Transition:
        jump = transition(self.kind, self.A, self.GQGt, self.B, mu,
                          input_matrix=self.input_matrix)
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
        return jump_update_predict(x, P, z, H, R, d, self.A, self.GQGt, self.B, mu,
                                   self.kind == 'exact')

    def stack(self, mus: NDArray[np.float64]) -> Transitions:
        """Return the transitions of every mu of mus (a run's distinct values) in one call."""
        return transitions(self.kind, self.A, self.GQGt, self.B, mus,
                           input_matrix=self.input_matrix)


def warm_up() -> None:
    """Compile the transition kernels for float64 arrays, or load them from numba's cache."""
    A, mus = np.eye(2), np.ones(1)
    euler(A, A, A[:, :1], 1.0)
    van_loan(A, A, 1.0)
    exact_input_matrix(A, A[:, :1], 1.0)
    euler_stack(A, A, A[:, :1], mus)
    van_loan_stack(A, A, mus)
    exact_input_stack(A, A[:, :1], mus)
    x, z, H = np.zeros(2), np.zeros(1), np.ones((1, 2))
    for exact in (False, True):
        jump_update_predict(x, A, z, H, np.eye(1), z, A, A, A[:, :1], 1.0, exact)
