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

"""Theorem 1 and Corollaries 1-2 of Fang & de Callafon 2011, and interval warnings for a node."""

from dataclasses import dataclass
from typing import Iterable, Unpack

from numpy.typing import ArrayLike

from tskf_ros.core.irregular.common import (CLUSTER_TOL, interval, IrregularError,
                                            MODULUS_RTOL, RANK_TOL)
from tskf_ros.core.irregular.intervals import (CheckOptions, distinct_eigenvalues, eigenspace,
                                               IntervalChecker, is_unstable, same_modulus,
                                               sees_fully)
from tskf_ros.core.matrices import as_matrix

UNDETECTABLE = '(A, C) is not detectable: assumption (A1) fails at every interval'


@dataclass(frozen=True)
class Theorem1Check:
    """Theorem 1 for an observed set of sampling intervals T."""

    intervals: tuple[int, ...]      # T, sorted
    pathological: tuple[int, ...]   # T n P
    degenerate: tuple[int, ...]     # T n D
    detectable: bool                # assumption (A1)

    @property
    def stable(self) -> bool:
        """Peak covariance stability is guaranteed: (A1) holds and T n D is empty."""
        return self.detectable and not self.degenerate


def theorem1(A: ArrayLike, C: ArrayLike, intervals: Iterable[int], *,
             criterion: str = 'paper', **tolerances: Unpack[CheckOptions]) -> Theorem1Check:
    """
    Theorem 1: if T n D = {} (and (A1)-(A3)) the peak covariance is stable.

    A sufficient condition only: a degenerate interval that occurs once does not make the
    covariance diverge.  tolerances are passed to the checks (rtol, rank_tol, ...).
    """
    T = sorted({interval(k) for k in intervals})
    if not T:
        raise IrregularError('theorem1 needs at least one sampling interval')
    check = IntervalChecker(A, C, criterion=criterion, **tolerances)
    return Theorem1Check(tuple(T), tuple(k for k in T if check.pathological(k)),
                         tuple(k for k in T if check.degenerate(k)), check.detectable)


def corollary1(A: ArrayLike, *, rtol: float = MODULUS_RTOL,
               cluster_tol: float = CLUSTER_TOL) -> bool:
    """
    Corollary 1: no two distinct eigenvalues with |mu| >= 1 share a modulus, so P = {}.

    Sufficient only: any complex unstable pair of a real A fails it (conjugates share a
    modulus), yet P is empty unless their angle is a rational multiple of pi.
    """
    eig = [e for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
           if is_unstable(e, True, rtol)]
    return not any(same_modulus(a.value, b.value, rtol)
                   for i, a in enumerate(eig) for b in eig[i + 1:])


def corollary2(A: ArrayLike, C: ArrayLike, *, rank_tol: float = RANK_TOL,
               rtol: float = MODULUS_RTOL, cluster_tol: float = CLUSTER_TOL) -> bool:
    """
    Corollary 2: C (Jordan coordinates) has full column rank on every eigencircle.

    For each set of two or more distinct eigenvalues with |mu| >= 1 and one modulus,
    C on their generalised eigenspaces has full column rank; then D = {} for every
    interval length.
    """
    A = as_matrix(A, 'A')
    C = as_matrix(C, 'C')
    eig = [e for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
           if is_unstable(e, True, rtol)]
    done: set[int] = set()
    for i, e in enumerate(eig):
        if i in done:
            continue
        circle = [j for j in range(len(eig)) if same_modulus(eig[j].value, e.value, rtol)]
        done.update(circle)
        if len(circle) > 1 and not sees_fully(
                C, [eigenspace(A, eig[j], chains=True) for j in circle], rank_tol):
            return False
    return True


def interval_warnings(A: ArrayLike, C: ArrayLike, intervals: Iterable[int], *,
                      criterion: str = 'paper') -> list[tuple[int, str]]:
    """
    (interval, reason) for every observed interval that is degenerate or pathological.

    For a node: A is the one-step transition of the nominal period (for a continuous
    model, expm(A_c h) or I + h A_c) and intervals are gaps in nominal periods.  Sorted
    by interval; empty when all is well.  An undetectable (A, C) is reported as interval
    1 (it fails assumption (A1) at every interval).
    """
    check = IntervalChecker(A, C, criterion=criterion)
    out: list[tuple[int, str]] = [] if check.detectable else [(1, UNDETECTABLE)]
    for k in sorted({interval(k) for k in intervals}):
        why = check.warning(k)
        if why is not None:
            out.append((k, why))
    return out
