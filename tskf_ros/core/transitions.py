"""
The jump of the time-scale filter over one graininess mu: F, Q_d and B_d.

Euler (Bohner & Wintz 2013, Table 3): F = I + mu A, Q_d = mu G Q G^T, B_d = mu B.
Exact (a continuous plant sampled at irregular instants): F = e^{A mu}, Q_d by Van Loan's
method (Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 1978),
B_d = int_0^mu e^{A s} ds B.
"""

from typing import NamedTuple
import warnings

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.matrices import is_invertible

Matrix = NDArray[np.float64]
TRANSITIONS = ('euler', 'exact')
# transitions kept per filter, keyed by mu (a stream at a fixed rate reuses a few)
CACHE_SIZE = 64


def van_loan(A: Matrix, GQGt: Matrix, mu: float) -> tuple[Matrix, Matrix]:
    """
    Exact (F, Q_d) of x' = A x + G w over mu: F = e^{A mu}, Q_d = int_0^mu F(s) GQG^T F(s)^T.

    Van Loan (1978): expm([[-A, GQG^T], [0, A^T]] h) = [[., F(h)^-1 Q_d(h)], [0, F(h)^T]],
    taken over h = mu / 2^k with ||A||_1 h <= 1 and doubled k times,
    F(2h) = F(h)^2, Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T: the one-shot block exponential
    holds e^{-A mu}, which for a stable A and a long mu (60 s of a spring-mass system) is
    so large that F and Q_d lose every digit (F came out 1e10, Q_d indefinite).
    """
    n = A.shape[0]
    reach = float(np.linalg.norm(A, 1)) * mu
    k = int(np.ceil(np.log2(reach))) if reach > 1 else 0
    h = mu / 2.0 ** k
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = GQGt
    M[n:, n:] = A.T
    E = _expm(M * h)
    F = E[n:, n:].T
    Qd = F @ E[:n, n:]
    with np.errstate(over='ignore', invalid='ignore'):
        for _ in range(k):
            # Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T, F(2h) = F(h)^2
            Qd = Qd + F @ Qd @ F.T
            F = F @ F
    return np.ascontiguousarray(F), (Qd + Qd.T) / 2


def exact_input_matrix(A: Matrix, B: Matrix, mu: float) -> Matrix:
    """B_d = int_0^mu e^{A s} ds B, from the block exponential expm([[A, B], [0, 0]] mu)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    return _expm(M * mu)[:n, n:]


def _expm(M: Matrix) -> Matrix:
    """
    Return scipy's expm(M), an overflow left in it (inf or nan), not printed as a warning.

    An exponential that overflows (e^{A mu} of an unstable A over a long jump) is a
    non-finite F that the filter refuses and the session counts as a reset; scipy's
    RuntimeWarning would only add two raw lines to a node's log.
    """
    with np.errstate(all='ignore'), warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        import scipy.linalg    # noqa: I900 - on first use: 0.4 s a node may not need
        return np.asarray(scipy.linalg.expm(M), dtype=float)


class Transition(NamedTuple):
    """The jump over one graininess mu, and whether I + mu A is invertible (Definition 2.12)."""

    F: Matrix
    Qd: Matrix
    Bd: Matrix
    regressive: bool


def transition(kind: str, A: Matrix, GQGt: Matrix, B: Matrix, mu: float) -> Transition:
    """(F, Q_d, B_d) for a jump of mu: the paper's Euler form or the exact sampled plant."""
    if kind == 'euler':
        # x(sigma) = (I + mu A) x + mu B u + mu G w, Var(mu G w) = mu GQG^T
        F = np.eye(A.shape[0]) + mu * A
        return Transition(F, mu * GQGt, mu * B, is_invertible(F))
    F, Qd = van_loan(A, GQGt, mu)
    # e^{A mu} is always invertible
    return Transition(F, Qd, exact_input_matrix(A, B, mu), True)


class TransitionCache(dict[float, Transition]):
    """The transitions of one model by mu, computed on first use, the last CACHE_SIZE kept."""

    def __init__(self, kind: str, A: Matrix, GQGt: Matrix, B: Matrix) -> None:
        super().__init__()
        self.kind, self.A, self.GQGt, self.B = kind, A, GQGt, B

    def __missing__(self, mu: float) -> Transition:
        jump = transition(self.kind, self.A, self.GQGt, self.B, mu)
        if len(self) >= CACHE_SIZE:
            del self[next(iter(self))]
        self[mu] = jump
        return jump
