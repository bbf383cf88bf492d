"""
Kalman filtering with irregularly sampled measurements (Fang & de Callafon, CDC 2011).

System Sigma_d, eqs. (1)-(2), on the integer grid k = 0, 1, ... of period T_s:

    x_{k+1} = A x_k + B u_k + w_k,     w ~ N(0, Q)
    y_{t_l} = C x_{t_l} + v_{t_l},     v ~ N(0, R), R > 0

with measurements only at the sampling instants t_0 < t_1 < ... (gamma_k = 1 there,
0 elsewhere) and T = {t_{l+1} - t_l} the set of sampling intervals.

Contents:
- the switching Kalman filter, eqs. (13)-(17), and the lifted filter over whole
  intervals, eqs. (3)-(8), both with the input u (`run_switching`, `run_lifted`);
- the sampling-interval checks of Section III: pathological intervals (Definition 2,
  eq. (18)), degenerate intervals (Definition 3, eqs. (19)-(20)), the test of
  Theorem 1, Corollaries 1 and 2, and `interval_warnings` for a node;
- Theorem 2 for scalar systems: the fixed points of X = f^k(g(X)), eqs. (22)-(25);
- not in the paper: the covariance of the time-scale filter (tskf_ros.core.timescale_kalman)
  after one jump of length J in an otherwise steady stream (`jump_covariance`).

Errata in the paper, and what this module does instead:
- eq. (3): Omega is printed [A^{k-1} B ... A I]; it is [A^{k-1} ... A I] (no B).
- eq. (10): 'A P A^1' is A P A^T.
- eq. (18): 'for all i, j' must read 'for some i != j' (two distinct eigenvalues); and
  it asks |mu| > 1 while Lemma 1 says |mu| >= 1.  A pair on the unit circle breaks the
  detectability of (A^k, C) just the same (A = diag(1, -1), C = [1, 1], k = 2), so by
  default eigenvalues with |mu| >= 1 count (`marginal=True`).
- Lemma 2 reads 'If T n P' for 'If T n P = {}'.
- eq. (20): 'rank deficient' is read as 'not of full column rank' (Corollary 2 says
  'full column rank'; a 1 x 2 block has full row rank yet one output never tells two
  merged modes apart).  See `degenerate_intervals` for the two readings of the group.
"""

from dataclasses import dataclass
import math
from typing import Iterable, Optional, Sequence

import numpy as np
import scipy.linalg

from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.timescale_kalman import (ArrayLike, as_matrix, check_covariance,
                                            TimeScaleKalmanFilter, van_loan)

# Default tolerances of the eigen-structure checks (all relative; see the functions).
CLUSTER_TOL = 1e-6      # eigenvalues closer than this * max(1, ||A||_2) are one eigenvalue
MODULUS_RTOL = 1e-8     # 'same modulus' and 'mu_i^k = mu_j^k' tolerance
NULL_TOL = 1e-7         # singular values of A - mu I below this * max(1, ||A||_2) span ker
RANK_TOL = 1e-8         # C U is rank deficient if sigma_min(C U) <= this * ||C||_2

CRITERIA = ('paper', 'detectability')
# log of the largest float: a power whose log is beyond this overflows
LOG_OVERFLOW = math.log(np.finfo(float).max)


class IrregularError(ValueError):
    """A model, interval set or sequence the irregular-sampling checks cannot use."""


# ---------------------------------------------------------------------------------------
# The switching filter (13)-(17) and the lifted filter (3)-(8)
# ---------------------------------------------------------------------------------------

def _check_model(A: ArrayLike, C: ArrayLike, Q: ArrayLike, R: ArrayLike,
                 B: ArrayLike = None) -> tuple[np.ndarray, ...]:
    """Return (A, C, Q, R, B) as checked float matrices (B: n x 1 zeros if None)."""
    A = as_matrix(A, 'A')
    n = A.shape[0]
    if A.shape != (n, n):
        raise IrregularError(f'A must be square, got shape {A.shape}')
    C = as_matrix(C, 'C')
    if C.shape[1] != n:
        raise IrregularError(f'C must have {n} columns, got shape {C.shape}')
    Q = check_covariance(as_matrix(Q, 'Q', (n, n)), 'Q')
    m = C.shape[0]
    R = check_covariance(as_matrix(R, 'R', (m, m)), 'R', definite=True)
    B = np.zeros((n, 1)) if B is None else as_matrix(B, 'B', column=True)
    if B.shape[0] != n:
        raise IrregularError(f'B must have {n} rows, got shape {B.shape}')
    return A, C, Q, R, B


@dataclass
class FilterHistory:
    """Priors and posteriors of a run: at every step (switching) or every sample (lifted)."""

    k: np.ndarray           # time indices of the rows
    x_prior: np.ndarray     # (N, n): xhat_k^-
    P_prior: np.ndarray     # (N, n, n): P_k^- (at a sampling instant: the peak covariance)
    x_post: np.ndarray      # (N, n): xhat_k^+
    P_post: np.ndarray      # (N, n, n): P_k^+


class SwitchingKalmanFilter:
    """
    The binary switching Kalman filter, Fang & de Callafon eqs. (13)-(17).

    `x`, `P` hold the current estimate; `predict(u)` moves it one step of T_s and
    `update(y)` corrects it, with `y=None` the explicit gamma_k = 0 branch.
    """

    def __init__(self, A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike,
                 x0: ArrayLike, P0: ArrayLike, B: ArrayLike = None) -> None:
        self.A, self.C, self.Q, self.R, self.B = _check_model(A, C, Q, R, B)
        n = self.A.shape[0]
        self.x = np.array(x0, dtype=float).reshape(n)
        self.P = check_covariance(as_matrix(P0, 'P0', (n, n)), 'P0')
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        self.K: Optional[np.ndarray] = None

    def predict(self, u: ArrayLike = None) -> None:
        """Time update from k-1 to k, eqs. (13)-(14) (= (9)-(10) between samples)."""
        u = np.zeros(self.B.shape[1]) if u is None else np.asarray(u, float).reshape(-1)
        # (13) xhat_k^- = A xhat_{k-1}^+ + B u_{k-1}
        self.x = self.A @ self.x + self.B @ u
        # (14) P_k^- = A P_{k-1}^+ A^T + Q
        self.P = self.A @ self.P @ self.A.T + self.Q
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def update(self, y: ArrayLike) -> None:
        """Measurement update at k, eqs. (15)-(17); y=None is gamma_k = 0, (11)-(12)."""
        if y is None:
            # (11)-(12) xhat_k^+ = xhat_k^-, P_k^+ = P_k^-
            self.K = None
            self.x_post, self.P_post = self.x.copy(), self.P.copy()
            return
        y = np.asarray(y, float).reshape(-1)
        C, P, R = self.C, self.P, self.R
        # S = C P_k^- C^T + R
        S = C @ P @ C.T + R
        # (15) K_k = P_k^- C^T S^-1
        K = np.linalg.solve(S, C @ P).T
        # (16) xhat_k^+ = xhat_k^- + K_k (y_k - C xhat_k^-)
        self.x = self.x + K @ (y - C @ self.x)
        # (17) P_k^+ = (I - K_k C) P_k^-, in Joseph form (I - KC) P (I - KC)^T + K R K^T,
        # equal in exact arithmetic and symmetric positive semi-definite in floating point
        I_KC = np.eye(P.shape[0]) - K @ C
        P = I_KC @ P @ I_KC.T + K @ R @ K.T
        self.P = (P + P.T) / 2
        self.K = K
        self.x_post, self.P_post = self.x.copy(), self.P.copy()


def _rows(values: ArrayLike, count: int, width: int, name: str) -> np.ndarray:
    """Return values as a (count, width) float array (None: zeros)."""
    if values is None:
        return np.zeros((count, width))
    a = np.asarray(values, dtype=float).reshape(count, -1)
    if a.shape[1] != width:
        raise IrregularError(f'{name} must have {width} columns, got {a.shape[1]}')
    return a


def run_switching(A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike, x0: ArrayLike,
                  P0: ArrayLike, y: ArrayLike, B: ArrayLike = None,
                  u: ArrayLike = None) -> FilterHistory:
    """
    Run eqs. (13)-(17) over k = 0..N-1; a NaN row of y (N x m) is gamma_k = 0.

    x0, P0 are the prior at k = 0 (xhat_0^-, P_0^-); u (N x p, optional) is the input,
    u_k acting from k to k + 1.
    """
    kf = SwitchingKalmanFilter(A, C, Q=Q, R=R, x0=x0, P0=P0, B=B)
    n, m, p = kf.A.shape[0], kf.C.shape[0], kf.B.shape[1]
    y = np.asarray(y, dtype=float).reshape(-1, m)
    N = y.shape[0]
    u = _rows(u, N, p, 'u')
    h = FilterHistory(np.arange(N), np.zeros((N, n)), np.zeros((N, n, n)),
                      np.zeros((N, n)), np.zeros((N, n, n)))
    for k in range(N):
        if k > 0:
            kf.predict(u[k - 1])
        h.x_prior[k], h.P_prior[k] = kf.x_prior, kf.P_prior
        gamma = not np.any(np.isnan(y[k]))
        kf.update(y[k] if gamma else None)
        h.x_post[k], h.P_post[k] = kf.x_post, kf.P_post
    return h


def lifted_matrices(A: ArrayLike, B: ArrayLike, kappa: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    (Phi, Gamma, Omega) of the lifted system, eq. (3), over an interval of kappa steps.

    Phi = A^kappa, Gamma = [A^{kappa-1} B ... A B  B], Omega = [A^{kappa-1} ... A  I]
    (the paper prints a stray B in Omega's first block).
    """
    A = as_matrix(A, 'A')
    B = as_matrix(B, 'B', column=True)
    kappa = _interval(kappa)
    powers = [np.eye(A.shape[0])]
    for _ in range(kappa):
        powers.append(A @ powers[-1])
    Phi = powers[kappa]
    Gamma = np.hstack([powers[kappa - 1 - i] @ B for i in range(kappa)])
    Omega = np.hstack([powers[kappa - 1 - i] for i in range(kappa)])
    return Phi, Gamma, Omega


def run_lifted(A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike, x0: ArrayLike,
               P0: ArrayLike, times: Sequence[int], y: ArrayLike, B: ArrayLike = None,
               u: ArrayLike = None) -> FilterHistory:
    """
    Run the lifted filter, eqs. (4)-(8), over the sampling instants only.

    times are the sampling instants t_0 < t_1 < ... (integers, t_0 = 0 is where x0, P0
    are the prior); y (L x m) the measurements there; u (t_last x p or longer) the
    input at every step.  Rows of the result are the sampling instants.
    """
    A, C, Q, R, B = _check_model(A, C, Q, R, B)
    n, m, p = A.shape[0], C.shape[0], B.shape[1]
    t = np.asarray(times, dtype=int).reshape(-1)
    if t.size == 0 or np.any(np.diff(t) <= 0):
        raise IrregularError('times must be a non-empty strictly increasing sequence')
    y = np.asarray(y, dtype=float).reshape(t.size, m)
    if u is None:
        u = np.zeros((int(t[-1] - t[0]), p))
    u = np.asarray(u, dtype=float).reshape(-1, p)
    if u.shape[0] < t[-1] - t[0]:
        raise IrregularError(f'u needs {t[-1] - t[0]} rows (one per step), got {u.shape[0]}')
    L = t.size
    h = FilterHistory(t.copy(), np.zeros((L, n)), np.zeros((L, n, n)),
                      np.zeros((L, n)), np.zeros((L, n, n)))
    x = np.array(x0, dtype=float).reshape(n)
    P = check_covariance(as_matrix(P0, 'P0', (n, n)), 'P0')
    for ell in range(L):
        if ell > 0:
            kappa = int(t[ell] - t[ell - 1])
            Phi, Gamma, Omega = lifted_matrices(A, B, kappa)
            # u~ = [u_{t_{l-1}}^T ... u_{t_l - 1}^T]^T
            u_tilde = u[t[ell - 1] - t[0]:t[ell] - t[0]].reshape(-1)
            # Delta = diag(Q, ..., Q), kappa blocks
            Delta = np.kron(np.eye(kappa), Q)
            # (4) xhat_{t_l}^- = Phi xhat_{t_{l-1}}^+ + Gamma u~
            x = Phi @ x + Gamma @ u_tilde
            # (5) P_{t_l}^- = Phi P_{t_{l-1}}^+ Phi^T + Omega Delta Omega^T
            P = Phi @ P @ Phi.T + Omega @ Delta @ Omega.T
        h.x_prior[ell], h.P_prior[ell] = x, P
        # (6) K = P^- C^T (C P^- C^T + R)^-1
        K = np.linalg.solve(C @ P @ C.T + R, C @ P).T
        # (7) xhat^+ = xhat^- + K (y - C xhat^-)
        x = x + K @ (y[ell] - C @ x)
        # (8) P^+ = (I - K C) P^-
        P = (np.eye(n) - K @ C) @ P
        P = (P + P.T) / 2
        h.x_post[ell], h.P_post[ell] = x, P
    return h


# ---------------------------------------------------------------------------------------
# Sampling-interval checks: Definitions 2 and 3, Theorem 1, Corollaries 1 and 2
# ---------------------------------------------------------------------------------------

def _interval(kappa: object) -> int:
    """Return kappa as a positive int, or raise."""
    try:
        k = int(kappa)
    except (TypeError, ValueError):
        raise IrregularError(f'a sampling interval must be an integer, got {kappa!r}') from None
    if k != kappa or k < 1:
        raise IrregularError(f'a sampling interval must be an integer >= 1, got {kappa!r}')
    return k


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
    lam = scipy.linalg.eigvals(A)
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


def _is_unstable(mu: Eigenvalue, marginal: bool, rtol: float) -> bool:
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
    max_interval = _interval(max_interval)
    eig = [e for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
           if _is_unstable(e, marginal, rtol)]
    out = []
    for kappa in range(2, max_interval + 1):
        if any(resonate(a.value, b.value, kappa, rtol)
               for i, a in enumerate(eig) for b in eig[i + 1:]):
            out.append(kappa)
    return out


def _null_basis(M: np.ndarray, *, dim: Optional[int] = None, tol: float) -> np.ndarray:
    """Orthonormal basis of ker M: the right singular vectors with sigma <= tol (or dim)."""
    _, s, Vh = np.linalg.svd(M)
    if dim is None:
        dim = max(1, int(np.sum(s <= tol)))
    return Vh[M.shape[1] - dim:].conj().T


def eigenspace(A: np.ndarray, mu: Eigenvalue, *, chains: bool,
               null_tol: float = NULL_TOL) -> np.ndarray:
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


def sees_fully(C: np.ndarray, bases: Sequence[np.ndarray], rank_tol: float = RANK_TOL) -> bool:
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
           if _is_unstable(e, marginal, rtol)]
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
               if _is_unstable(e, True, rtol))


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
                    if _is_unstable(e, marginal, rtol)]
        self.spaces = [eigenspace(self.A, e, chains=criterion == 'paper', null_tol=null_tol)
                       for e in self.eig]
        self.detectable = is_detectable(self.A, self.C, rank_tol=rank_tol, rtol=rtol,
                                        cluster_tol=cluster_tol, null_tol=null_tol)

    def merged(self, kappa: int) -> list[tuple[int, int]]:
        """Pairs (i, j), i < j, of unstable eigenvalues that coincide after kappa steps."""
        kappa = _interval(kappa)
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
             criterion: str = 'paper', **tolerances: float) -> Theorem1Check:
    """
    Theorem 1: if T n D = {} (and (A1)-(A3)) the peak covariance is stable.

    A sufficient condition only: a degenerate interval that occurs once does not make the
    covariance diverge.  tolerances are passed to the checks (rtol, rank_tol, ...).
    """
    T = sorted({_interval(k) for k in intervals})
    if not T:
        raise IrregularError('theorem1 needs at least one sampling interval')
    check = IntervalChecker(A, C, criterion=criterion, **tolerances)
    return Theorem1Check(tuple(T), tuple(k for k in T if check.pathological(k)),
                         tuple(k for k in T if check.degenerate(k)), check.detectable)


def _pick(d: dict, *keys: str) -> dict:
    return {k: v for k, v in d.items() if k in keys}


def corollary1(A: ArrayLike, *, rtol: float = MODULUS_RTOL,
               cluster_tol: float = CLUSTER_TOL) -> bool:
    """
    Corollary 1: no two distinct eigenvalues with |mu| >= 1 share a modulus, so P = {}.

    Sufficient only: any complex unstable pair of a real A fails it (conjugates share a
    modulus), yet P is empty unless their angle is a rational multiple of pi.
    """
    eig = [e for e in distinct_eigenvalues(A, cluster_tol=cluster_tol)
           if _is_unstable(e, True, rtol)]
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
           if _is_unstable(e, True, rtol)]
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
    for k in sorted({_interval(k) for k in intervals}):
        why = check.warning(k)
        if why is not None:
            out.append((k, why))
    return out


def _fmt(z: complex) -> str:
    if abs(z.imag) <= 1e-12 * max(1.0, abs(z)):
        return f'{z.real:.6g}'
    return f'{abs(z):.6g}*exp({np.angle(z):+.6g}j)'


# ---------------------------------------------------------------------------------------
# Theorem 2: scalar peak-covariance bounds
# ---------------------------------------------------------------------------------------

def scalar_peak_map(a: float, c: float, q: float, r: float, kappa: int, X: float) -> float:
    """f^kappa(g(X)), eqs. (22)-(23) for n = 1: the peak covariance one interval later."""
    # (23) g(X) = X - X c (c X c + r)^-1 c X = r X / (c^2 X + r)
    Y = r * X / (c * c * X + r)
    for _ in range(_interval(kappa)):
        # (22) f(Y) = a Y a + q
        Y = a * a * Y + q
    return Y


def scalar_fixed_point(a: float, c: float, q: float, r: float, kappa: int) -> float:
    """
    Return the unique non-negative solution of X = f^kappa(g(X)) (closed form).

    f^kappa(Y) = a^{2 kappa} Y + q_kappa with q_kappa = q sum_{i<kappa} a^{2i}, so the
    equation is c^2 X^2 + b X - q_kappa r = 0 with b = r (1 - a^{2 kappa}) - q_kappa c^2;
    the root is taken in the form that does not cancel.
    """
    kappa = _interval(kappa)
    a, c, q, r = float(a), float(c), float(q), float(r)
    if not r > 0 or q < 0:
        raise IrregularError(f'need r > 0 and q >= 0, got r = {r}, q = {q}')
    if c == 0 and abs(a) >= 1:
        raise IrregularError('c = 0 with |a| >= 1: (a, c) is not detectable (A1)')
    if abs(a) > 1 and 2 * kappa * math.log(abs(a)) > LOG_OVERFLOW:
        # a^{2 kappa} overflows: the peak covariance after such an interval is beyond any
        # float (X ~ a^{2 kappa} (r / c^2 + q / (a^2 - 1))), so the bound is +inf
        return math.inf
    a2k = a ** (2 * kappa)
    qk = q * kappa if a * a == 1 else q * (a2k - 1) / (a * a - 1)
    if c == 0:
        return qk / (1 - a2k)
    c2 = c * c
    b = r * (1 - a2k) - qk * c2
    root = np.sqrt(b * b + 4 * c2 * qk * r)
    return float((root - b) / (2 * c2) if b <= 0 else 2 * qk * r / (b + root))


def scalar_peak_bounds(a: float, c: float, q: float, r: float, tau: int,
                       eta: int) -> tuple[float, float]:
    """
    Theorem 2, eq. (25): (P_bar_tau, P_bar_eta), fixed points of X = f^k(g(X)), k = tau, eta.

    With intervals in [tau, eta] and a peak covariance started in [P_bar_tau, P_bar_eta],
    every later peak covariance stays there, and its limit points too.  The proof asks
    |a| >= 1 (so that f^tau <= f^eta); for |a| < 1 the same holds on
    [0, q / (1 - a^2)], which contains both fixed points.
    """
    tau, eta = _interval(tau), _interval(eta)
    if tau > eta:
        raise IrregularError(f'need tau <= eta, got tau = {tau}, eta = {eta}')
    return scalar_fixed_point(a, c, q, r, tau), scalar_fixed_point(a, c, q, r, eta)


# ---------------------------------------------------------------------------------------
# Not in the papers: the time-scale filter's covariance after one jump
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class JumpCovariance:
    """Covariances of the time-scale filter around one jump of length J (see jump_covariance)."""

    J: float
    period: float
    transition: str
    P_steady: np.ndarray            # predicted covariance on the nominal stream
    P_steady_corrected: np.ndarray  # corrected covariance on the nominal stream
    P_peak: np.ndarray              # predicted covariance at t* + J, before its measurement
    P_after: np.ndarray             # corrected covariance at t* + J
    recovery_steps: int             # nominal steps after t* + J until the peak is back
    regressive: bool                # I + J A invertible (always True for 'exact')


def _correct(P: np.ndarray, C: np.ndarray, Rd: np.ndarray) -> np.ndarray:
    """Measurement update of the covariance with R_d, in Joseph form."""
    # S = C P C^T + R_d, L = P C^T S^-1
    L = np.linalg.solve(C @ P @ C.T + Rd, C @ P).T
    # P(t|t) = (I - L C) P (I - L C)^T + L R_d L^T
    I_LC = np.eye(P.shape[0]) - L @ C
    P = I_LC @ P @ I_LC.T + L @ Rd @ L.T
    return (P + P.T) / 2


def _predict(P: np.ndarray, F: np.ndarray, Qd: np.ndarray) -> np.ndarray:
    # P(sigma) = F P(t|t) F^T + Q_d
    P = F @ P @ F.T + Qd
    return (P + P.T) / 2


def _transition(kf: TimeScaleKalmanFilter, mu: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q_d) of kf.transition_matrices(mu), without the unused B_d (an expm less)."""
    if kf.transition == 'euler':
        return np.eye(kf.n) + mu * kf.A, mu * kf.GQGt
    return van_loan(kf.A, kf.GQGt, mu)


def steady_covariance(model: LinearModel, period: float, *, transition: str = 'euler',
                      tol: float = 1e-13, max_steps: int = 100_000) -> np.ndarray:
    """
    Predicted covariance of the time-scale filter on period * Z in its steady state.

    The fixed point of P -> F (P - P C^T (C P C^T + R/h)^-1 C P) F^T + Q_d with
    (F, Q_d) the filter's transition over h = period: the stabilising solution of
    the discrete algebraic Riccati equation of B&W Table 3 at constant mu = h.
    """
    kf = model.make_filter(transition, allow_nonregressive=True)
    F, Qd = _transition(kf, period)
    C, Rd = kf.C, kf.R / period
    try:
        P = scipy.linalg.solve_discrete_are(F.T, C.T, Qd, Rd)
        P = (P + P.T) / 2
        resid = _predict(_correct(P, C, Rd), F, Qd) - P
        if np.all(np.isfinite(P)) and np.max(np.abs(resid)) <= 1e-8 * max(1.0, np.max(P)):
            return P
    except (np.linalg.LinAlgError, ValueError):
        pass
    # solve_discrete_are needs a regular symplectic pencil; iterate the map otherwise
    P = kf.P.copy()
    for _ in range(max_steps):
        P_new = _predict(_correct(P, C, Rd), F, Qd)
        if np.max(np.abs(P_new - P)) <= tol * max(1.0, np.max(np.abs(P_new))):
            return P_new
        P = P_new
    raise IrregularError(f'the Riccati iteration at period {period} did not converge')


def jump_covariance(model: LinearModel, J: float, *, period: float = 1.0,
                    transition: str = 'euler', recovery: float = 0.1,
                    every: Optional[int] = None,
                    P_steady: Optional[np.ndarray] = None) -> JumpCovariance:
    """
    How bad is the point after a gap of J: the time-scale filter around one jump.

    Setting (defined here, not in the papers): points every `period` h, so mu = h
    and the filter (B&W Table 3; F, Q_d from `transition`, R_d = R / mu) is in its
    steady state P_steady; at one point t* the next point is t* + J (mu(t*) = J), then
    the points are every h again.  Then

        P_c(t*)    = correction of P_steady with R_d = R / J   (Table 3 weighs the
                     measurement before a jump by its graininess)
        P_peak     = F_J P_c(t*) F_J^T + Q_d(J)                 the predicted covariance
                     at t* + J, the peak (Fang & de Callafon's P_{t_l})
        P_after    = correction of P_peak with R / h            the estimate at t* + J

    recovery_steps counts the nominal steps after t* + J until trace(P_pred) is within
    (1 + recovery) trace(P_steady).  J = h gives P_peak = P_steady.  With every = N the
    jump recurs after every N nominal steps, and the P's are those of the periodic
    steady state (the fixed point of the period map) instead.  P_steady, if given, is
    `steady_covariance(model, period, transition=transition)` computed once.
    """
    J, period = float(J), float(period)
    if not (J > 0 and period > 0):
        raise IrregularError(f'J and period must be > 0, got J = {J}, period = {period}')
    kf = model.make_filter(transition, allow_nonregressive=True)
    C, R = kf.C, kf.R
    F_h, Q_h = _transition(kf, period)
    F_J, Q_J = _transition(kf, J)
    regressive = transition == 'exact' or np.linalg.cond(np.eye(kf.n) + J * kf.A) < 1e12
    P_ss = (steady_covariance(model, period, transition=transition) if P_steady is None
            else np.asarray(P_steady, dtype=float))

    def over_jump(P: np.ndarray) -> np.ndarray:
        return _predict(_correct(P, C, R / J), F_J, Q_J)

    def nominal(P: np.ndarray) -> np.ndarray:
        return _predict(_correct(P, C, R / period), F_h, Q_h)

    P_before = P_ss
    if every is not None:
        every = _interval(every)
        P = P_ss
        for _ in range(100_000):
            P_new = over_jump(P)
            for _ in range(every):
                P_new = nominal(P_new)
            if np.max(np.abs(P_new - P)) <= 1e-13 * max(1.0, np.max(np.abs(P_new))):
                break
            P = P_new
        else:
            raise IrregularError('the periodic Riccati iteration did not converge')
        P_before = P_new
    P_peak = over_jump(P_before)
    P = P_peak
    steps, target = 0, (1 + recovery) * np.trace(P_ss)
    while np.trace(P) > target and steps < 100_000:
        P = nominal(P)
        steps += 1
    return JumpCovariance(J, period, transition, P_before, _correct(P_before, C, R / period),
                          P_peak, _correct(P_peak, C, R / period), steps, bool(regressive))
