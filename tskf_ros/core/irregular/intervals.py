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
Pathological and degenerate sampling intervals: Fang & de Callafon 2011, Definitions 2-3.

kappa is pathological (eq. (18)) when two distinct eigenvalues mu_i != mu_j of A with
|mu_i| = |mu_j| >= 1 satisfy (mu_i / mu_j)^kappa = 1, and degenerate (eqs. (19)-(20)) when
C restricted to the eigenvalues that kappa merges is not of full column rank.
"""

from dataclasses import dataclass
from typing import Optional, Sequence, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.irregular.common import (CLUSTER_TOL, CRITERIA, interval, IrregularError,
                                            MODULUS_RTOL, NULL_TOL, RANK_TOL)
from tskf_ros.core.matrices import as_matrix


@dataclass(frozen=True)
class Eigenvalue:
    """One distinct eigenvalue of A: the mean of a cluster of computed eigenvalues."""

    value: complex
    multiplicity: int       # algebraic: the cluster size

    @property
    def modulus(self) -> float:
        """|mu|."""
        return abs(self.value)


def distinct_eigenvalues(A: ArrayLike, *, cluster_tol: float = CLUSTER_TOL
                         ) -> list[Eigenvalue]:
    """
    Distinct eigenvalues of A with their algebraic multiplicities.

    A Jordan block of size h is computed as h eigenvalues spread by about
    ||A|| eps^(1/h) (1.5e-8 ||A|| for h = 2); eigenvalues closer than
    cluster_tol * max(1, ||A||_2) (single linkage) are one eigenvalue, whose value
    is the cluster mean: the mean of a perturbed Jordan block is accurate to about
    eps ||A|| (it is a trace), unlike its members.  Raise cluster_tol for blocks
    of size 3 or more (eps^(1/3) = 6e-6).
    """
    A = as_matrix(A, 'A')
    # LAPACK's geev, as scipy.linalg.eigvals (equal to 1e-12: the test); no scipy import
    lam = np.linalg.eigvals(A)
    tol = cluster_tol * max(1.0, float(np.linalg.norm(A, 2)))
    parent = list(range(lam.size))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for i in range(lam.size):
        for j in range(i + 1, lam.size):
            if abs(lam[i] - lam[j]) <= tol:
                parent[root(j)] = root(i)
    groups: dict[int, list[complex]] = {}
    for i in range(lam.size):
        groups.setdefault(root(i), []).append(complex(lam[i]))
    out = [Eigenvalue(complex(np.mean(g)), len(g)) for g in groups.values()]
    return sorted(out, key=lambda e: (-e.modulus, np.angle(e.value)))


def is_unstable(mu: Eigenvalue, marginal: bool, rtol: float) -> bool:
    """|mu| >= 1 (marginal) or |mu| > 1, within rtol."""
    return mu.modulus >= 1 - rtol if marginal else mu.modulus > 1 + rtol


def same_modulus(a: complex, b: complex, rtol: float = MODULUS_RTOL) -> bool:
    """| |a| - |b| | <= rtol * max(|a|, |b|): the 'same eigencircle' test of eq. (18)."""
    return abs(abs(a) - abs(b)) <= rtol * max(abs(a), abs(b))


def resonate(a: complex, b: complex, kappa: int, rtol: float = MODULUS_RTOL) -> bool:
    """
    Test (a / b)^kappa = 1 within tolerance: same modulus and kappa (arg a - arg b) in 2 pi Z.

    The angle is tested as |wrap(kappa (arg a - arg b))| <= kappa * rtol: an eigenvalue
    known to a relative error rtol has its argument known to rtol radians, and the
    kappa-th power multiplies that by kappa.
    """
    if not same_modulus(a, b, rtol):
        return False
    d = kappa * (np.angle(a) - np.angle(b))
    return abs(np.angle(np.exp(1j * d))) <= kappa * rtol


def pathological_intervals(A: ArrayLike, max_interval: int, *, marginal: bool = True,
                           rtol: float = MODULUS_RTOL,
                           cluster_tol: float = CLUSTER_TOL) -> list[int]:
    """
    Return the pathological intervals in 2..max_interval: the set P, Def. 2, eq. (18).

    kappa is pathological when two distinct eigenvalues mu_i != mu_j of A with
    |mu_i| = |mu_j| >= 1 (> 1 with marginal=False, as eq. (18) prints) satisfy
    (mu_i / mu_j)^kappa = 1: sampled every kappa steps they land on one point.

    Tolerances: distinct eigenvalues as in `distinct_eigenvalues` (cluster_tol);
    'same modulus' is | |mu_i| - |mu_j| | <= rtol max(|mu_i|, |mu_j|); the power is
    1 when kappa (arg mu_i - arg mu_j) is within kappa * rtol of a multiple of 2 pi.
    """
    max_interval = interval(max_interval)
    eig = [e for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
           if is_unstable(e, marginal, rtol)]
    out = []
    for kappa in range(2, max_interval + 1):
        if any(resonate(a.value, b.value, kappa, rtol)
               for i, a in enumerate(eig) for b in eig[i + 1:]):
            out.append(kappa)
    return out


def _null_basis(M: NDArray[np.complex128], *, dim: Optional[int] = None, tol: float
                ) -> NDArray[np.complex128]:
    """Orthonormal basis of ker M: the right singular vectors with sigma <= tol (or dim)."""
    _, s, Vh = np.linalg.svd(M)
    if dim is None:
        dim = max(1, int(np.sum(s <= tol)))
    return Vh[M.shape[1] - dim:].conj().T


def eigenspace(A: NDArray[np.float64], mu: Eigenvalue, *, chains: bool,
               null_tol: float = NULL_TOL) -> NDArray[np.complex128]:
    """
    Orthonormal basis of ker(A - mu I) or, with chains, of ker(A - mu I)^h.

    These span the columns of the Jordan basis M that belong to mu: the leading
    column of each Jordan block (eigenvectors) or every column of its blocks
    (the generalised eigenspace, of dimension h = the algebraic multiplicity).
    Computing them by SVD avoids the Jordan form itself, which is not continuous in A.
    The eigenspace dimension is the number of singular values of A - mu I at most
    null_tol * max(1, ||A||_2).
    """
    n = A.shape[0]
    M = A - mu.value * np.eye(n)
    if chains:
        return _null_basis(np.linalg.matrix_power(M, mu.multiplicity), dim=mu.multiplicity,
                           tol=0.0)
    return _null_basis(M, tol=null_tol * max(1.0, float(np.linalg.norm(A, 2))))


def sees_fully(C: NDArray[np.float64], bases: Sequence[NDArray[np.complex128]],
               rank_tol: float = RANK_TOL) -> bool:
    """
    Test whether C on span(bases) has full column rank (the C_J block of eq. (20)).

    The columns of the Jordan basis for a set of eigenvalues span the same subspace as
    these bases, and full column rank of C on a subspace does not depend on the basis,
    so the test is made on an orthonormal basis U of the span: C U is rank deficient
    when sigma_min(C U) <= rank_tol * ||C||_2 (or C has fewer rows than U has columns).
    """
    V = np.hstack(bases)
    U, _ = np.linalg.qr(V)
    if C.shape[0] < U.shape[1]:
        return False
    s = np.linalg.svd(C @ U, compute_uv=False)
    return bool(s[-1] > rank_tol * max(float(np.linalg.norm(C, 2)), np.finfo(float).tiny))


def degenerate_intervals(A: ArrayLike, C: ArrayLike, max_interval: int, *,
                         criterion: str = 'paper', marginal: bool = True,
                         rtol: float = MODULUS_RTOL, rank_tol: float = RANK_TOL,
                         cluster_tol: float = CLUSTER_TOL,
                         null_tol: float = NULL_TOL) -> list[int]:
    """
    Return the degenerate intervals in 2..max_interval: the set D, Def. 3, eq. (20).

    kappa in P is degenerate when C restricted to the eigenvalues merged by kappa is
    rank deficient (not of full column rank).  Two readings of 'the block':

    - criterion='paper' (eqs. (19)-(20) as printed): the group G_{kappa,alpha} is every
      unstable eigenvalue of modulus alpha that has a partner mu_j with
      (mu_i / mu_j)^kappa = 1, and its block of C_J = C M holds all columns of its
      Jordan blocks (the generalised eigenspaces);
    - criterion='detectability': the groups are the classes of equal mu^kappa, and only
      the eigenvectors count.  By the factorisation of Lemma 2, ker(A^kappa - mu^kappa I)
      is the sum of ker(A - mu_i I) over the class, so this is exactly the PBH test that
      (A^kappa, C) is detectable at mu^kappa.  Its D is a subset of the paper's; the two
      agree when the merged eigenvalues are semisimple (all examples of the paper).

    Tolerances: eigenvalues and 'same modulus' as in `pathological_intervals`;
    'rank deficient' is sigma_min(C U) <= rank_tol * ||C||_2 with U an orthonormal
    basis of the group's (generalised) eigenvectors (`sees_fully`, `eigenspace`).
    """
    if criterion not in CRITERIA:
        raise IrregularError(f'criterion must be one of {CRITERIA}, got {criterion!r}')
    A = as_matrix(A, 'A')
    C = as_matrix(C, 'C')
    if C.shape[1] != A.shape[0]:
        raise IrregularError(f'C must have {A.shape[0]} columns, got shape {C.shape}')
    chains = criterion == 'paper'
    eig = [e for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
           if is_unstable(e, marginal, rtol)]
    spaces = [eigenspace(A, e, chains=chains, null_tol=null_tol) for e in eig]
    out = []
    for kappa in pathological_intervals(A, max_interval, marginal=marginal, rtol=rtol,
                                        cluster_tol=cluster_tol):
        for group in _groups(eig, kappa, criterion, rtol):
            if not sees_fully(C, [spaces[i] for i in group], rank_tol):
                out.append(kappa)
                break
    return out


def _groups(eig: Sequence[Eigenvalue], kappa: int, criterion: str,
            rtol: float) -> list[list[int]]:
    """Index groups of >= 2 eigenvalues merged by kappa: G_{kappa,alpha} or mu^kappa classes."""
    pairs = {(i, j) for i in range(len(eig)) for j in range(len(eig))
             if i != j and resonate(eig[i].value, eig[j].value, kappa, rtol)}
    groups: list[list[int]] = []
    seen: set[int] = set()
    for i in range(len(eig)):
        if i in seen or not any(p[0] == i for p in pairs):
            continue
        if criterion == 'paper':
            # eq. (19): all resonating eigenvalues on the eigencircle of modulus alpha
            g = [j for j in range(len(eig)) if any(p[0] == j for p in pairs)
                 and same_modulus(eig[j].value, eig[i].value, rtol)]
        else:
            # one class of equal mu^kappa
            g = [i] + [j for j in range(len(eig)) if (i, j) in pairs]
        seen.update(g)
        groups.append(g)
    return groups


def is_detectable(A: ArrayLike, C: ArrayLike, *, rank_tol: float = RANK_TOL,
                  rtol: float = MODULUS_RTOL, cluster_tol: float = CLUSTER_TOL,
                  null_tol: float = NULL_TOL) -> bool:
    """Assumption (A1): C sees every eigenvector of A with |mu| >= 1 (PBH test)."""
    A = as_matrix(A, 'A')
    C = as_matrix(C, 'C')
    return all(sees_fully(C, [eigenspace(A, e, chains=False, null_tol=null_tol)], rank_tol)
               for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
               if is_unstable(e, True, rtol))


class CheckOptions(TypedDict, total=False):
    """The keyword options of IntervalChecker besides the criterion (see its arguments)."""

    marginal: bool
    rtol: float
    rank_tol: float
    cluster_tol: float
    null_tol: float


class IntervalChecker:
    """
    Definitions 2-3 and (A1) for one (A, C), asked one interval at a time.

    The eigen-analysis is done once; `pathological(k)` and `degenerate(k)` then cost
    O(n^2) resonance tests (plus a rank test per merged group) whatever k is, so a stream
    that keeps showing new intervals pays a bounded price per new interval instead of
    re-enumerating 2..max(T) (`pathological_intervals` does that to list the whole set).
    Same tolerances and criteria as `pathological_intervals` / `degenerate_intervals`.
    """

    def __init__(self, A: ArrayLike, C: ArrayLike, *, criterion: str = 'paper',
                 marginal: bool = True, rtol: float = MODULUS_RTOL,
                 rank_tol: float = RANK_TOL, cluster_tol: float = CLUSTER_TOL,
                 null_tol: float = NULL_TOL) -> None:
        if criterion not in CRITERIA:
            raise IrregularError(f'criterion must be one of {CRITERIA}, got {criterion!r}')
        self.A = as_matrix(A, 'A')
        self.C = as_matrix(C, 'C')
        if self.C.shape[1] != self.A.shape[0]:
            raise IrregularError(f'C must have {self.A.shape[0]} columns, got shape '
                                 f'{self.C.shape}')
        self.criterion, self.rtol, self.rank_tol = criterion, rtol, rank_tol
        self.eig = [e for e in distinct_eigenvalues(self.A, cluster_tol=cluster_tol)
                    if is_unstable(e, marginal, rtol)]
        self.spaces = [eigenspace(self.A, e, chains=criterion == 'paper', null_tol=null_tol)
                       for e in self.eig]
        self.detectable = is_detectable(self.A, self.C, rank_tol=rank_tol, rtol=rtol,
                                        cluster_tol=cluster_tol, null_tol=null_tol)

    def merged(self, kappa: int) -> list[tuple[int, int]]:
        """Pairs (i, j), i < j, of unstable eigenvalues that coincide after kappa steps."""
        kappa = interval(kappa)
        if kappa < 2:
            return []
        return [(i, j) for i in range(len(self.eig)) for j in range(i + 1, len(self.eig))
                if resonate(self.eig[i].value, self.eig[j].value, kappa, self.rtol)]

    def pathological(self, kappa: int) -> bool:
        """Tell whether kappa is in P (Definition 2, eq. (18))."""
        return bool(self.merged(kappa))

    def degenerate(self, kappa: int) -> bool:
        """Tell whether kappa is in D (Definition 3, eq. (20))."""
        if not self.pathological(kappa):
            return False
        return any(not sees_fully(self.C, [self.spaces[i] for i in group], self.rank_tol)
                   for group in _groups(self.eig, kappa, self.criterion, self.rtol))

    def warning(self, kappa: int) -> Optional[str]:
        """Return why kappa is pathological or degenerate, or None (see interval_warnings)."""
        pairs = self.merged(kappa)
        if not pairs:
            return None
        what = ', '.join(sorted({_fmt(self.eig[i].value) for pair in pairs for i in pair}))
        if self.degenerate(kappa):
            return (f'degenerate (Definition 3): eigenvalues {what} coincide after {kappa} '
                    f'steps and C cannot tell them apart; (A^{kappa}, C) is not detectable')
        return (f'pathological (Definition 2): eigenvalues {what} coincide after {kappa} '
                'steps, but C sees them apart (not degenerate)')


def _fmt(z: complex) -> str:
    if abs(z.imag) <= 1e-12 * max(1.0, abs(z)):
        return f'{z.real:.6g}'
    return f'{abs(z):.6g}*exp({np.angle(z):+.6g}j)'
