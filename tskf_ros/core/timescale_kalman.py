"""
The Kalman filter on time scales (Bohner & Wintz 2013, Table 3; Cai et al., Table I).

System on a time scale T, with graininess mu(t) = sigma(t) - t:

    x^Delta(t) = A x(t) + B u(t) + G w(t),      y(t) = C x(t) + D + v(t)
    w ~ (0, Q delta(t, s)),  v ~ (0, R delta(t, s)),  R > 0

Table 3 (with Cai's output offset D), at a right-scattered point t (mu > 0):

    K(t)       = (I + mu A) P C^T (R + mu C P C^T)^-1
    xhat^Delta = A xhat + B u + K [y - C xhat - D]
    P^Delta    = A P + (I + mu A) P A^T + G Q G^T
                 - (I + mu A) P C^T (R + mu C P C^T)^-1 C P (I + mu A^T)

and, by the "simple useful formula" f(sigma) = f + mu f^Delta (B&W Theorem 2.5d),
xhat(sigma) = xhat + mu xhat^Delta and P(sigma) = P + mu P^Delta.  Table 3 is a
one-step *predictor*: the estimate at sigma(t) uses y up to t only.

Expanding, the step is exactly a textbook predictive discrete Kalman filter with
F = I + mu A, Q_d = mu G Q G^T, R_d = R / mu (the white noise of intensity R seen
through one point of measure mu).  `step` also returns the *corrected* estimate at t,
the measurement update of that discrete filter (not in the papers):

    L        = P C^T (C P C^T + R / mu)^-1
    x(t|t)   = xhat + L (y - C xhat - D)
    P(t|t)   = (I - L C) P (I - L C)^T + L (R / mu) L^T       (Joseph form)

At right-dense points (mu = 0) Table 3 reduces to the Kalman-Bucy filter of Table 2:

    xhat' = A xhat + B u + K (y - C xhat - D),   K = P C^T R^-1
    P'    = A P + P A^T + G Q G^T - P C^T R^-1 C P

which `integrate` solves over a stretch with scipy's adaptive Runge-Kutta.

Besides the paper's Euler transition I + mu A (exact on a true time scale), the filter
can discretise a jump as a continuous plant sampled at irregular instants
(`transition='exact'`: F = expm(A mu), Q_d by Van Loan's method, B_d = int e^{A s} ds B).
"""

from dataclasses import dataclass
import math
from typing import Callable, Optional

import numpy as np
import scipy.integrate
import scipy.linalg

ArrayLike = object

TRANSITIONS = ('euler', 'exact')


class FilterError(ValueError):
    """Bad model, bad step, or bad measurement given to the time-scale filter."""


class NonRegressiveError(FilterError):
    """A step whose I + mu A is singular (Definition 2.12): refused, the state is sound."""


def as_matrix(value: ArrayLike, name: str, shape: Optional[tuple] = None, *,
              column: bool = False) -> np.ndarray:
    """
    Return value as a finite float 2-D array.

    Scalars become 1x1; a 1-D sequence becomes a row (or a column with column=True,
    as for G = [0, 1] in Bohner & Wintz Example 3.20).
    """
    try:
        m = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'{name} is not a numeric matrix: {exc}') from None
    if m.ndim == 0:
        m = m.reshape(1, 1)
    elif m.ndim == 1:
        m = m.reshape(-1, 1) if column else m.reshape(1, -1)
    if m.ndim != 2:
        raise FilterError(f'{name} must be a matrix, got an array with {m.ndim} dimensions')
    if not np.all(np.isfinite(m)):
        raise FilterError(f'{name} has non-finite entries')
    if shape is not None and m.shape != shape:
        raise FilterError(f'{name} must have shape {shape}, got {m.shape}')
    return m


def check_covariance(m: np.ndarray, name: str, *, definite: bool = False,
                     tol: float = 1e-9) -> np.ndarray:
    """Raise unless m is symmetric and positive semi-definite (definite: positive definite)."""
    if m.shape[0] != m.shape[1]:
        raise FilterError(f'{name} must be square, got shape {m.shape}')
    scale = max(1.0, float(np.max(np.abs(m))))
    if not np.allclose(m, m.T, rtol=0.0, atol=tol * scale):
        raise FilterError(f'{name} is not symmetric: max |{name} - {name}^T| = '
                          f'{np.max(np.abs(m - m.T)):.3g}')
    sym = m / 2 + m.T / 2           # halves first: m + m^T overflows near 1e308
    eig = np.linalg.eigvalsh(sym)
    if definite and eig[0] <= 0:
        raise FilterError(f'{name} must be positive definite, smallest eigenvalue {eig[0]:.3g}')
    if eig[0] < -tol * scale:
        raise FilterError(f'{name} is indefinite: smallest eigenvalue {eig[0]:.3g}')
    return sym


def is_invertible(M: np.ndarray, rtol: float = 1e-12) -> bool:
    """
    Tell whether a small square matrix is numerically invertible.

    |det M| is compared with Hadamard's bound prod_i |row_i| (|det M| <= that bound, with
    equality for orthogonal rows), so the test does not depend on the scale of M.
    """
    if M.shape == (1, 1):
        return float(M[0, 0]) != 0.0
    if M.shape == (2, 2):       # closed form
        (a, b), (c, d) = M.tolist()
        return _invertible_2x2(a, b, c, d, rtol)
    det, bound = float(np.linalg.det(M)), float(np.prod(np.linalg.norm(M, axis=1)))
    return bound > 0 and abs(det) > rtol * bound


def _invertible_2x2(a: float, b: float, c: float, d: float, rtol: float = 1e-12) -> bool:
    """is_invertible of [[a, b], [c, d]] on plain floats."""
    det, bound = a * d - b * c, ((a * a + b * b) * (c * c + d * d)) ** 0.5
    return bound > 0 and abs(det) > rtol * bound


def is_psd(P: np.ndarray, tol: float = 1e-9) -> bool:
    """
    Tell whether a symmetric matrix is positive semi-definite within tol (relative).

    Up to 2 x 2 the eigenvalue test is done in closed form (the filter's hot path runs it
    twice per step); larger P goes through a Cholesky factorisation of P + tol * scale * I,
    which succeeds exactly when the smallest eigenvalue of P is above -tol * scale.
    """
    n = P.shape[0]
    if n == 1:
        a = P.item()
        return a >= -tol * max(1.0, abs(a))
    if n == 2:
        (a, b), (_, c) = P.tolist()
        # smallest eigenvalue of [[a, b], [b, c]]: (a + c) / 2 - sqrt(((a - c) / 2)^2 + b^2)
        # (a - c) * (a - c), not ** 2, which raises OverflowError past 1e154
        h = (a - c) / 2
        return (a + c) / 2 - (h * h + b * b) ** 0.5 >= -tol * max(1.0, abs(a), abs(c))
    eps = tol * max(1.0, float(np.max(np.abs(np.diag(P)))))
    try:
        np.linalg.cholesky(P + eps * np.eye(n))
    except np.linalg.LinAlgError:
        return False
    return True


def van_loan(A: np.ndarray, GQGt: np.ndarray, mu: float) -> tuple[np.ndarray, np.ndarray]:
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
    E = scipy.linalg.expm(M * h)
    F = E[n:, n:].T
    Qd = F @ E[:n, n:]
    with np.errstate(over='ignore', invalid='ignore'):
        for _ in range(k):
            # Q_d(2h) = Q_d(h) + F(h) Q_d(h) F(h)^T, F(2h) = F(h)^2
            Qd = Qd + F @ Qd @ F.T
            F = F @ F
    return F, (Qd + Qd.T) / 2


def exact_input_matrix(A: np.ndarray, B: np.ndarray, mu: float) -> np.ndarray:
    """B_d = int_0^mu e^{A s} ds B, from the block exponential expm([[A, B], [0, 0]] mu)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    return scipy.linalg.expm(M * mu)[:n, n:]


@dataclass(slots=True)
class StepResult:
    """
    What one step produced: the corrected estimate at t and the prediction at sigma(t).

    Not frozen: a frozen dataclass costs 0.6 us more to build, a seventh of a scalar step.
    """

    mu: float
    x_corrected: np.ndarray
    P_corrected: np.ndarray
    x_predicted: np.ndarray
    P_predicted: np.ndarray
    innovation: np.ndarray
    S: np.ndarray


# transitions kept per filter, keyed by mu (a stream at a fixed rate reuses a few)
JUMP_CACHE_SIZE = 64
_FLOAT = np.dtype(float)
_INF = float('inf')
_NOT_POSITIVE = 'R + mu C P C^T is not positive at mu = {}: P has lost semi-definiteness'


def _checked(v: ArrayLike, size: int, name: str) -> np.ndarray:
    """Return v as a finite float vector of `size` entries; a float64 array is not copied."""
    if v.__class__ is not np.ndarray or v.dtype is not _FLOAT or v.shape != (size,):
        return TimeScaleKalmanFilter._vector(v, size, name)
    # a sum is finite when every entry is; only a sum that is not needs the full check
    if not math.isfinite(v.sum()) and not np.isfinite(v).all():
        raise FilterError(f'{name} has non-finite entries: {v}')
    return v


def _float(v: ArrayLike, name: str) -> float:
    """Return a one-entry measurement as a finite float."""
    if v.__class__ is float:
        f = v
    elif v.__class__ is np.ndarray and v.dtype is _FLOAT and v.shape == (1,):
        f = v.item()
    else:
        return TimeScaleKalmanFilter._vector(v, 1, name).item()
    if not math.isfinite(f):
        raise FilterError(f'{name} has non-finite entries: {v}')
    return f


def _floats(v: ArrayLike, size: int, name: str) -> list:
    """Return v as a list of `size` finite floats."""
    if v.__class__ is np.ndarray and v.dtype is _FLOAT and v.shape == (size,):
        f = v.tolist()
        if not all(map(math.isfinite, f)):
            raise FilterError(f'{name} has non-finite entries: {v}')
        return f
    return TimeScaleKalmanFilter._vector(v, size, name).tolist()


def _model_matrix(name: str) -> property:
    """Make a model-matrix property: assigning it is checked and re-derives the caches."""
    private = '_' + name

    def get(self: 'TimeScaleKalmanFilter') -> np.ndarray:
        return getattr(self, private)

    def put(self: 'TimeScaleKalmanFilter', value: ArrayLike) -> None:
        old = getattr(self, private)
        new = as_matrix(value, name, column=name in ('G', 'B'))
        if name == 'D':
            new = new.reshape(-1)
        if new.shape != old.shape:
            raise FilterError(f'{name} must keep its shape {old.shape}, got {new.shape}')
        if name in ('Q', 'R'):
            new = check_covariance(new, name, definite=name == 'R')
        setattr(self, private, new)
        self._prepare()

    return property(get, put, doc=f'The model matrix {name} (assigning it is checked).')


class TimeScaleKalmanFilter:
    """
    Kalman filter on a time scale: Bohner & Wintz Table 3 with Cai's offset D.

    After construction `x`, `P` hold the estimate at the first point t0.  Each
    `step(mu, y)` uses the measurement at the current point t and moves `x`, `P`
    to sigma(t) = t + mu (the paper's predictor), and keeps the corrected
    estimate at t in `x_corrected`, `P_corrected`.

    The model is checked once, here; a step checks only mu, y and u, with plain-float
    tests.  The model matrices can be assigned later (checked, same shape).
    """

    A = _model_matrix('A')
    C = _model_matrix('C')
    G = _model_matrix('G')
    Q = _model_matrix('Q')
    R = _model_matrix('R')
    B = _model_matrix('B')
    D = _model_matrix('D')

    def __init__(self, A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike,
                 G: ArrayLike = None, B: ArrayLike = None, D: ArrayLike = None,
                 x0: ArrayLike, P0: ArrayLike, transition: str = 'euler',
                 allow_nonregressive: bool = False) -> None:
        A = as_matrix(A, 'A')
        n = A.shape[0]
        if A.shape != (n, n):
            raise FilterError(f'A must be square, got shape {A.shape}')
        C = as_matrix(C, 'C')
        if C.shape[1] != n:
            raise FilterError(f'C must have {n} columns to match A {A.shape}, '
                              f'got shape {C.shape}')
        p = C.shape[0]
        G = np.eye(n) if G is None else as_matrix(G, 'G', column=True)
        if G.shape[0] != n:
            raise FilterError(f'G must have {n} rows to match A, got shape {G.shape}')
        r = G.shape[1]
        Q = check_covariance(as_matrix(Q, 'Q'), 'Q')
        if Q.shape != (r, r):
            raise FilterError(f'Q must have shape {(r, r)} to match G {G.shape}, '
                              f'got {Q.shape}')
        R = check_covariance(as_matrix(R, 'R'), 'R', definite=True)
        if R.shape != (p, p):
            raise FilterError(f'R must have shape {(p, p)} to match C {C.shape}, '
                              f'got {R.shape}')
        if B is None:
            B = np.zeros((n, 1))
        else:
            B = as_matrix(B, 'B', column=True)
            if B.shape[0] != n:
                raise FilterError(f'B must have {n} rows, got shape {B.shape}')
        D = np.zeros(p) if D is None else as_matrix(D, 'D').reshape(-1)
        if D.shape != (p,):
            raise FilterError(f'D must have {p} entries to match C, got {D.size}')
        if transition not in TRANSITIONS:
            raise FilterError(f'transition must be one of {TRANSITIONS}, got {transition!r}')
        self._A, self._C, self._G, self._Q, self._R, self._B, self._D = A, C, G, Q, R, B, D
        self._transition = transition
        # Definition 2.12 asks I + mu A to be invertible; Table 3 itself never inverts it,
        # so a user who knowingly runs a non-regressive model (as Cai et al. do with
        # system (1) at mu = 1) can say so.  Off by default: such a step is refused.
        self.allow_nonregressive = bool(allow_nonregressive)
        self._prepare()
        self.x = self._vector(x0, n, 'x0')
        P0m = as_matrix(P0, 'P0')
        if P0m.shape != (n, n):
            raise FilterError(f'P0 must have shape {(n, n)}, got {P0m.shape}')
        self.P = check_covariance(P0m, 'P0')
        self.x_corrected: Optional[np.ndarray] = None
        self.P_corrected: Optional[np.ndarray] = None

    def _prepare(self) -> None:
        """Derive what every step reuses from the (checked) model matrices."""
        A, C, B = self._A, self._C, self._B
        n, p = A.shape[0], C.shape[0]
        self.GQGt = self._G @ self._Q @ self._G.T
        self._I = np.eye(n)
        self._zero = np.zeros(n)
        self._jumps: dict = {}
        self._uses_B = bool(np.any(B))
        self._uses_D = bool(np.any(self._D))
        # plain floats for n <= 2 with one output: numpy's per-call cost dominates there
        self._small = n if n <= 2 and p == 1 else 0
        self._a, self._c = A.ravel().tolist(), C.ravel().tolist()
        self._r, self._d = float(self._R[0, 0]), float(self._D[0])
        self._gqg, self._b = self.GQGt.ravel().tolist(), B.tolist()

    @property
    def transition(self) -> str:
        """'euler' (the paper's I + mu A) or 'exact' (e^{A mu}); assigning it is checked."""
        return self._transition

    @transition.setter
    def transition(self, value: str) -> None:
        if value not in TRANSITIONS:
            raise FilterError(f'transition must be one of {TRANSITIONS}, got {value!r}')
        self._transition = value
        self._jumps = {}

    @property
    def n(self) -> int:
        """State dimension."""
        return self._A.shape[0]

    @property
    def p(self) -> int:
        """Measurement dimension."""
        return self._C.shape[0]

    @staticmethod
    def _vector(value: ArrayLike, size: int, name: str) -> np.ndarray:
        try:
            v = np.array(value, dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise FilterError(f'{name} is not numeric: {exc}') from None
        if v.shape != (size,):
            raise FilterError(f'{name} must have {size} entries, got {v.size}')
        if not np.all(np.isfinite(v)):
            raise FilterError(f'{name} has non-finite entries: {v}')
        return v

    def _input(self, u: ArrayLike) -> np.ndarray:
        if u is None:
            return np.zeros(self._B.shape[1])
        return _checked(u, self._B.shape[1], 'u')

    def transition_matrices(self, mu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, Q_d, B_d) for a jump of mu: the paper's Euler form or the exact sampled plant."""
        if self._transition == 'euler':
            # x(sigma) = (I + mu A) x + mu B u + mu G w, Var(mu G w) = mu GQG^T
            return self._I + mu * self._A, mu * self.GQGt, mu * self._B
        F, Qd = van_loan(self._A, self.GQGt, mu)
        return F, Qd, exact_input_matrix(self._A, self._B, mu)

    def _jump(self, mu: float) -> tuple:
        """
        Return (F, Q_d, B_d, regressive, their entries as float lists) for mu, cached.

        `regressive` tells whether I + mu A is invertible (Definition 2.12; always true
        for the exact transition, whose e^{A mu} is).
        """
        hit = self._jumps.get(mu)
        if hit is None:
            F, Qd, Bd = self.transition_matrices(mu)
            regressive = self._transition == 'exact' or is_invertible(F)
            hit = (F, Qd, Bd, regressive, F.ravel().tolist(), Qd.ravel().tolist(),
                   Bd.tolist())
            if len(self._jumps) >= JUMP_CACHE_SIZE:
                self._jumps.pop(next(iter(self._jumps)))
            self._jumps[mu] = hit
        if not hit[3] and not self.allow_nonregressive:
            raise NonRegressiveError(
                f'I + mu A is singular at mu = {mu}: A is not regressive on this time '
                'scale (Bohner & Wintz Definition 2.12); the step is refused')
        return hit

    def check_mu(self, mu: float) -> float:
        """Return mu as float, or raise if it is not a finite positive graininess."""
        if mu.__class__ is not float:
            try:
                mu = float(mu)
            except (TypeError, ValueError):
                raise FilterError(f'mu must be a number, got {mu!r}') from None
        if 0.0 < mu < _INF:
            return mu
        if not math.isfinite(mu):
            raise FilterError(f'mu must be finite, got {mu}')
        if mu < 0:
            raise FilterError(f'mu must be >= 0 (time runs forward), got {mu}')
        raise FilterError('mu = 0 is a right-dense point: use integrate() for a dense stretch')

    def _measurement_noise(self, R: ArrayLike) -> np.ndarray:
        """R for one step: a variance > 0 (R I) or a p x p positive definite matrix."""
        if isinstance(R, (float, int)) and not isinstance(R, bool):
            R = float(R)
            if not (0.0 < R < _INF):
                raise FilterError(f'R must be a finite variance > 0, got {R}')
            return np.eye(self.p) * R
        R = check_covariance(as_matrix(R, 'R'), 'R', definite=True)
        if R.shape != (self.p, self.p):
            raise FilterError(f'R must have shape {(self.p, self.p)}, got {R.shape}')
        return R

    def step(self, mu: float, y: ArrayLike, u: ArrayLike = None, *,
             R: ArrayLike = None) -> StepResult:
        """
        Advance from t to sigma(t) = t + mu with the measurement y(t) (Table 3).

        `y=None` is an explicit missing measurement: only the time update is made
        (K = 0), which is what Table 3 gives as R -> infinity.  `R` replaces the model's
        R for this step only (a variance: R I, or a p x p matrix), as FilterPy's
        `update(z, R=...)`.

        The step is computed as the corrected estimate at t followed by the transition,

            x(sigma) = F x(t|t) + B_d u,   P(sigma) = F P(t|t) F^T + Q_d,

        with F = I + mu A, Q_d = mu GQG^T, B_d = mu B on the paper's time scale.  That is
        Table 3's algebra: (I + mu A) W^T = K with W = (R + mu C P C^T)^-1 C P, so
        P + mu P^Delta = F (P - mu P C^T W) F^T + mu GQG^T and
        xhat + mu xhat^Delta = F (xhat + mu W^T e) + mu B u, and it takes two n x n
        products where the terms of P^Delta take four.  With one output and n <= 2 the
        step runs on plain floats, Table 3 term by term for n = 1.
        """
        mu = self.check_mu(mu)
        R = self._R if R is None else self._measurement_noise(R)
        small = self._small
        if small:
            y = None if y is None else _float(y, 'y')
            u = None if u is None else _floats(u, self._B.shape[1], 'u')
            if small == 1:
                x_c, P_c, x_new, P_new, e, S = self.scalar_step(mu, self.x.item(),
                                                                self.P.item(), y, u, R.item())
                res = StepResult(mu, np.array((x_c,)), np.array(((P_c,),)),
                                 np.array((x_new,)), np.array(((P_new,),)), np.array((e,)),
                                 np.array(((S,),)))
            else:
                res = self._step_pair(mu, y, u, R)
        else:
            if y is not None:
                y = _float(y, 'y') if self._C.shape[0] == 1 else _checked(y, self.p, 'y')
            if u is not None:
                u = _checked(u, self._B.shape[1], 'u')
            res = self._step_matrix(mu, y, u, R)
        self.x, self.P = res.x_predicted, res.P_predicted
        self.x_corrected, self.P_corrected = res.x_corrected, res.P_corrected
        return res

    def _step_matrix(self, mu: float, y: Optional[np.ndarray], u: Optional[np.ndarray],
                     R: np.ndarray) -> StepResult:
        """
        Make the step with numpy, for any n and p.

        ndarray.dot rather than @: on the small arrays of a filter it costs a third as much
        per call (bench/bench_core.py), and a step makes about ten such products.
        """
        F, Qd, Bd = self._jump(mu)[:3]
        x, P, C = self.x, self.P, self._C
        p = C.shape[0]
        if y is None:
            innovation = np.full(p, np.nan)
            S = np.full((p, p), np.nan)
            x_c, P_c = x.copy(), P.copy()
        elif p == 1:
            # the same with C a row c: C P and L are vectors, R + mu C P C^T a float
            c = self._C[0]
            e = y - float(c.dot(x)) - self._d
            CP = c.dot(P)
            RmuCPC = R.item() + mu * float(CP.dot(c))
            if not RmuCPC > 0:
                raise FilterError(_NOT_POSITIVE.format(mu))
            s = RmuCPC / mu
            L = CP * (mu / RmuCPC)
            x_c = x + L * e
            P_c = P - L[:, None] * CP
            P_c += (L * s - CP)[:, None] * L
            innovation, S = np.array((e,)), np.array(((s,),))
        else:
            # innovation y - C xhat - D
            innovation = y - C.dot(x)
            if self._uses_D:
                innovation = innovation - self._D
            CP = C.dot(P)
            # R + mu C P C^T
            RmuCPC = R + mu * CP.dot(C.T)
            # W = (R + mu C P C^T)^-1 C P
            if p == 2:
                (a, b), (c, d) = RmuCPC.tolist()
                W = np.array(((d, -b), (-c, a))).dot(CP) / (a * d - b * c)
            else:
                W = np.linalg.solve(RmuCPC, CP)
            # corrected estimate at t: measurement update with R_d = R / mu;
            # S = C P C^T + R / mu = (R + mu C P C^T) / mu, so L = P C^T S^-1 = mu W^T
            S = RmuCPC / mu
            L = mu * W.T
            x_c = x + L.dot(innovation)
            # Joseph form (I - L C) P (I - L C)^T + L R_d L^T, which keeps P(t|t) positive
            # semi-definite for any L, expanded with the symmetric P and S = C P C^T + R_d:
            # P - L (C P) + (L S - P C^T) L^T, O(n^2 p) where it is two n x n products
            P_c = P - L.dot(CP) + (L.dot(S) - CP.T).dot(L.T)
        # the transition: x(sigma) = F x(t|t) + B_d u, P(sigma) = F P(t|t) F^T + Q_d
        x_new = F.dot(x_c)
        if u is not None and self._uses_B:
            x_new = x_new + Bd.dot(u)
        P_new = F.dot(P_c).dot(F.T)
        P_new += Qd
        P_new += P_new.T            # numpy buffers the overlapping transpose
        P_new *= 0.5
        # 0 * v is 0 for a finite v and NaN for inf or NaN, so this is 0 exactly when
        # every entry of x and P is finite
        zero = self._zero
        if (P_new.dot(zero) + x_new).dot(zero) != 0.0:
            raise FilterError(f'step with mu = {mu} overflowed; the filter state is unchanged')
        return StepResult(mu, x_c, P_c, x_new, P_new, innovation, S)

    def _bu(self, Bd: list, u: Optional[list]) -> list:
        """B_d u as floats (zeros without an input)."""
        if u is None or not self._uses_B:
            return [0.0] * len(Bd)
        return [sum(b * v for b, v in zip(row, u)) for row in Bd]

    def scalar_step(self, mu: float, x: float, P: float, y: Optional[float],
                    u: Optional[list], r: float) -> tuple:
        """
        Make the step for n = p = 1 on plain floats: Table 3 term by term (Euler).

        From (x, P) at t with the variance r in place of R; returns the floats
        (x(t|t), P(t|t), x(sigma), P(sigma), innovation, S) and changes nothing: `step`
        wraps them in a StepResult and moves the filter, and a caller that checks them
        first (the estimator session) moves it itself.  mu > 0 finite, y (None: no
        measurement) and u (a list of B's columns, or None) finite, r > 0: not checked
        here.  Raises FilterError as `step` does.
        """
        a, c, d, gqg = self._a[0], self._c[0], self._d, self._gqg[0]
        if self._transition == 'euler':
            F = 1.0 + mu * a
            if F == 0.0 and not self.allow_nonregressive:
                self._jump(mu)          # raises NonRegressiveError
            Qd = mu * gqg
            if y is None:       # B_d u = (mu B) u
                bu = self._bu([[mu * b for b in self._b[0]]], u)[0]
            else:               # B u, for xhat^Delta
                bu = self._bu(self._b, u)[0]
        else:
            hit = self._jump(mu)
            F, Qd, bu = hit[4][0], hit[5][0], self._bu(hit[6], u)[0]
        if y is None:
            nan = math.nan
            x_c, P_c, e, S = x, P, nan, nan
            x_new = F * x + bu
            P_new = F * P * F + Qd
        else:
            # innovation y - C xhat - D
            e = y - c * x - d
            CP = c * P
            # R + mu C P C^T and W = (R + mu C P C^T)^-1 C P
            RmuCPC = r + mu * (CP * c)
            if not RmuCPC > 0:
                raise FilterError(_NOT_POSITIVE.format(mu))
            W = CP / RmuCPC
            # corrected estimate: L = mu W^T, Joseph form with R_d = R / mu
            S = RmuCPC / mu
            L = mu * W
            x_c = x + L * e
            I_LC = 1.0 - L * c
            P_c = I_LC * P * I_LC + L * (r / mu) * L
            if self._transition == 'euler':
                # K = (I + mu A) W^T; xhat^Delta = A xhat + B u + K [y - C xhat - D]
                K = F * W
                x_delta = a * x + bu + K * e
                # P^Delta = AP + (I+muA) P A^T + GQG^T - (I+muA) P C^T (.)^-1 C P (I+muA^T)
                P_delta = a * P + F * P * a + gqg - K * CP * F
                # f(sigma) = f + mu f^Delta
                x_new = x + mu * x_delta
                P_new = P + mu * P_delta
            else:
                x_new = F * x_c + bu
                P_new = F * P_c * F + Qd
        P_new = (P_new + P_new) / 2    # as (P + P^T) / 2: it overflows where that does
        if not math.isfinite(x_new + P_new):
            raise FilterError(f'step with mu = {mu} overflowed; the filter state is unchanged')
        return x_c, P_c, x_new, P_new, e, S

    def _step_pair(self, mu: float, y: Optional[float], u: Optional[list],
                   R: np.ndarray) -> StepResult:
        """Make the step for n = 2, p = 1 on plain floats: P(t|t), then F P(t|t) F^T + Q_d."""
        (x0, x1), ((p00, p01), (p10, p11)) = self.x.tolist(), self.P.tolist()
        if self._transition == 'euler':
            a00, a01, a10, a11 = self._a
            f00, f01, f10, f11 = 1.0 + mu * a00, mu * a01, mu * a10, 1.0 + mu * a11
            if not self.allow_nonregressive and not _invertible_2x2(f00, f01, f10, f11):
                self._jump(mu)          # raises NonRegressiveError
            q00, q01, q10, q11 = (mu * q for q in self._gqg)
            b0, b1 = self._bu([[mu * b for b in row] for row in self._b], u)
        else:
            hit = self._jump(mu)
            (f00, f01, f10, f11), (q00, q01, q10, q11) = hit[4], hit[5]
            b0, b1 = self._bu(hit[6], u)
        if y is None:
            nan = math.nan
            xc0, xc1, c00, c01, c10, c11, e, S = x0, x1, p00, p01, p10, p11, nan, nan
        else:
            c0, c1 = self._c
            r = R.item()
            # innovation y - C xhat - D; C P; R + mu C P C^T; L = mu W^T
            e = y - (c0 * x0 + c1 * x1) - self._d
            h0, h1 = c0 * p00 + c1 * p10, c0 * p01 + c1 * p11
            RmuCPC = r + mu * (h0 * c0 + h1 * c1)
            if not RmuCPC > 0:
                raise FilterError(_NOT_POSITIVE.format(mu))
            S = RmuCPC / mu
            l0, l1 = mu * (h0 / RmuCPC), mu * (h1 / RmuCPC)
            xc0, xc1 = x0 + l0 * e, x1 + l1 * e
            # Joseph form P - L (C P) + (L S - P C^T) L^T
            n0, n1 = l0 * S - h0, l1 * S - h1
            c00, c01 = p00 - l0 * h0 + n0 * l0, p01 - l0 * h1 + n0 * l1
            c10, c11 = p10 - l1 * h0 + n1 * l0, p11 - l1 * h1 + n1 * l1
        # x(sigma) = F x(t|t) + B_d u, P(sigma) = F P(t|t) F^T + Q_d (symmetrised)
        xn0, xn1 = f00 * xc0 + f01 * xc1 + b0, f10 * xc0 + f11 * xc1 + b1
        t00, t01 = f00 * c00 + f01 * c10, f00 * c01 + f01 * c11
        t10, t11 = f10 * c00 + f11 * c10, f10 * c01 + f11 * c11
        n00 = t00 * f00 + t01 * f01 + q00
        n11 = t10 * f10 + t11 * f11 + q11
        n00, n11 = (n00 + n00) / 2, (n11 + n11) / 2   # as (P + P^T) / 2, overflow included
        n01 = ((t00 * f10 + t01 * f11 + q01) + (t10 * f00 + t11 * f01 + q10)) / 2
        if not math.isfinite(xn0 + xn1 + n00 + n01 + n11):
            raise FilterError(f'step with mu = {mu} overflowed; the filter state is unchanged')
        return StepResult(mu, np.array((xc0, xc1)), np.array(((c00, c01), (c10, c11))),
                          np.array((xn0, xn1)), np.array(((n00, n01), (n01, n11))),
                          np.array((e,)), np.array(((S,),)))

    def integrate(self, duration: float, y: Callable[[float], ArrayLike],
                  u: Optional[Callable[[float], ArrayLike]] = None, *,
                  rtol: float = 1e-9, atol: float = 1e-12) -> None:
        """
        Run the Kalman-Bucy filter (Table 2) over a right-dense stretch [t, t + duration].

        y(s) and u(s) give the continuous measurement and input at s in [0, duration]
        (time from the start of the stretch).  The ODEs for xhat and P are solved
        together by scipy's RK45 with the given tolerances; the tests show the
        covariance matches the closed-form scalar Riccati solution to ~1e-9.
        """
        duration = float(duration)
        if not np.isfinite(duration) or duration < 0:
            raise FilterError(f'duration must be finite and >= 0, got {duration}')
        if duration == 0:
            return
        n, A, C, D = self.n, self.A, self.C, self.D
        Rinv = np.linalg.inv(self.R)
        B, GQGt = self.B, self.GQGt

        def rhs(s: float, z: np.ndarray) -> np.ndarray:
            xh = z[:n]
            P = z[n:].reshape(n, n)
            # K = P C^T R^-1
            K = P @ C.T @ Rinv
            ys = np.asarray(y(s), dtype=float).reshape(-1)
            us = self._input(None if u is None else u(s))
            dx = A @ xh + B @ us + K @ (ys - C @ xh - D)
            dP = A @ P + P @ A.T + GQGt - K @ C @ P
            return np.concatenate([dx, ((dP + dP.T) / 2).reshape(-1)])

        z0 = np.concatenate([self.x, self.P.reshape(-1)])
        sol = scipy.integrate.solve_ivp(rhs, (0.0, duration), z0, method='RK45',
                                        rtol=rtol, atol=atol)
        if not sol.success:
            raise FilterError(f'Kalman-Bucy integration failed: {sol.message}')
        zf = sol.y[:, -1]
        P = zf[n:].reshape(n, n)
        self.x, self.P = zf[:n], (P + P.T) / 2

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Return a copy of (x, P), for history and rewinding."""
        return self.x.copy(), self.P.copy()

    def set_state(self, x: ArrayLike, P: ArrayLike) -> None:
        """Restore an estimate and covariance (checked)."""
        x = self._vector(x, self.n, 'x')
        P = check_covariance(as_matrix(P, 'P', (self.n, self.n)), 'P')
        self.x, self.P = x, P
