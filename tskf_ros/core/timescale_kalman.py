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
    if M.shape == (2, 2):       # closed form: the filter's hot path runs this every step
        (a, b), (c, d) = M.tolist()
        det, bound = a * d - b * c, ((a * a + b * b) * (c * c + d * d)) ** 0.5
    else:
        det, bound = float(np.linalg.det(M)), float(np.prod(np.linalg.norm(M, axis=1)))
    return bound > 0 and abs(det) > rtol * bound


def is_psd(P: np.ndarray, tol: float = 1e-9) -> bool:
    """
    Tell whether a symmetric matrix is positive semi-definite within tol (relative).

    Up to 2 x 2 the eigenvalue test is done in closed form (the filter's hot path runs it
    twice per step); larger P goes through a Cholesky factorisation of P + tol * scale * I,
    which succeeds exactly when the smallest eigenvalue of P is above -tol * scale.
    """
    n = P.shape[0]
    d = np.diag(P)
    scale = max(1.0, float(np.max(np.abs(d))))
    eps = tol * scale
    if n == 1:
        return float(P[0, 0]) >= -eps
    if n == 2:
        a, b, c = float(P[0, 0]), float(P[0, 1]), float(P[1, 1])
        # smallest eigenvalue of [[a, b], [b, c]]: (a + c) / 2 - sqrt(((a - c) / 2)^2 + b^2)
        return (a + c) / 2 - ((a - c) ** 2 / 4 + b * b) ** 0.5 >= -eps
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


@dataclass(frozen=True)
class StepResult:
    """What one step produced: the corrected estimate at t and the prediction at sigma(t)."""

    mu: float
    x_corrected: np.ndarray
    P_corrected: np.ndarray
    x_predicted: np.ndarray
    P_predicted: np.ndarray
    innovation: np.ndarray
    S: np.ndarray


class TimeScaleKalmanFilter:
    """
    Kalman filter on a time scale: Bohner & Wintz Table 3 with Cai's offset D.

    After construction `x`, `P` hold the estimate at the first point t0.  Each
    `step(mu, y)` uses the measurement at the current point t and moves `x`, `P`
    to sigma(t) = t + mu (the paper's predictor), and keeps the corrected
    estimate at t in `x_corrected`, `P_corrected`.
    """

    def __init__(self, A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike,
                 G: ArrayLike = None, B: ArrayLike = None, D: ArrayLike = None,
                 x0: ArrayLike, P0: ArrayLike, transition: str = 'euler',
                 allow_nonregressive: bool = False) -> None:
        self.A = as_matrix(A, 'A')
        n = self.A.shape[0]
        if self.A.shape != (n, n):
            raise FilterError(f'A must be square, got shape {self.A.shape}')
        self.C = as_matrix(C, 'C')
        if self.C.shape[1] != n:
            raise FilterError(f'C must have {n} columns to match A {self.A.shape}, '
                              f'got shape {self.C.shape}')
        p = self.C.shape[0]
        self.G = np.eye(n) if G is None else as_matrix(G, 'G', column=True)
        if self.G.shape[0] != n:
            raise FilterError(f'G must have {n} rows to match A, got shape {self.G.shape}')
        r = self.G.shape[1]
        self.Q = check_covariance(as_matrix(Q, 'Q'), 'Q')
        if self.Q.shape != (r, r):
            raise FilterError(f'Q must have shape {(r, r)} to match G {self.G.shape}, '
                              f'got {self.Q.shape}')
        self.R = check_covariance(as_matrix(R, 'R'), 'R', definite=True)
        if self.R.shape != (p, p):
            raise FilterError(f'R must have shape {(p, p)} to match C {self.C.shape}, '
                              f'got {self.R.shape}')
        if B is None:
            self.B = np.zeros((n, 1))
        else:
            self.B = as_matrix(B, 'B', column=True)
            if self.B.shape[0] != n:
                raise FilterError(f'B must have {n} rows, got shape {self.B.shape}')
        self.D = np.zeros(p) if D is None else as_matrix(D, 'D').reshape(-1)
        if self.D.shape != (p,):
            raise FilterError(f'D must have {p} entries to match C, got {self.D.size}')
        if transition not in TRANSITIONS:
            raise FilterError(f'transition must be one of {TRANSITIONS}, got {transition!r}')
        self.transition = transition
        # Definition 2.12 asks I + mu A to be invertible; Table 3 itself never inverts it,
        # so a user who knowingly runs a non-regressive model (as Cai et al. do with
        # system (1) at mu = 1) can say so.  Off by default: such a step is refused.
        self.allow_nonregressive = bool(allow_nonregressive)
        self.GQGt = self.G @ self.Q @ self.G.T
        self._I = np.eye(n)
        self.x = self._vector(x0, n, 'x0')
        P0m = as_matrix(P0, 'P0')
        if P0m.shape != (n, n):
            raise FilterError(f'P0 must have shape {(n, n)}, got {P0m.shape}')
        self.P = check_covariance(P0m, 'P0')
        self.x_corrected: Optional[np.ndarray] = None
        self.P_corrected: Optional[np.ndarray] = None

    @property
    def n(self) -> int:
        """State dimension."""
        return self.A.shape[0]

    @property
    def p(self) -> int:
        """Measurement dimension."""
        return self.C.shape[0]

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
            return np.zeros(self.B.shape[1])
        return self._vector(u, self.B.shape[1], 'u')

    def transition_matrices(self, mu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, Q_d, B_d) for a jump of mu: the paper's Euler form or the exact sampled plant."""
        if self.transition == 'euler':
            # x(sigma) = (I + mu A) x + mu B u + mu G w, Var(mu G w) = mu GQG^T
            return self._I + mu * self.A, mu * self.GQGt, mu * self.B
        F, Qd = van_loan(self.A, self.GQGt, mu)
        return F, Qd, exact_input_matrix(self.A, self.B, mu)

    def check_mu(self, mu: float) -> float:
        """Return mu as float, or raise if it is not a finite positive graininess."""
        try:
            mu = float(mu)
        except (TypeError, ValueError):
            raise FilterError(f'mu must be a number, got {mu!r}') from None
        if not np.isfinite(mu):
            raise FilterError(f'mu must be finite, got {mu}')
        if mu < 0:
            raise FilterError(f'mu must be >= 0 (time runs forward), got {mu}')
        if mu == 0:
            raise FilterError('mu = 0 is a right-dense point: use integrate() for a dense stretch')
        return mu

    def step(self, mu: float, y: ArrayLike, u: ArrayLike = None) -> StepResult:
        """
        Advance from t to sigma(t) = t + mu with the measurement y(t); Table 3 verbatim.

        `y=None` is an explicit missing measurement: only the time update is made
        (K = 0), which is what Table 3 gives as R -> infinity.
        """
        mu = self.check_mu(mu)
        u = self._input(u)
        x, P, A, C, eye = self.x, self.P, self.A, self.C, self._I
        if self.transition == 'euler':
            I_muA = eye + mu * A
            if not self.allow_nonregressive and not is_invertible(I_muA):
                raise NonRegressiveError(
                    f'I + mu A is singular at mu = {mu}: A is not regressive on this time '
                    'scale (Bohner & Wintz Definition 2.12); the step is refused')
        F, Qd, Bd = self.transition_matrices(mu)
        if y is None:
            innovation = np.full(self.p, np.nan)
            S = np.full((self.p, self.p), np.nan)
            x_c, P_c = x.copy(), P.copy()
            x_new = F @ x + Bd @ u
            P_new = F @ P @ F.T + Qd
        else:
            y = self._vector(y, self.p, 'y')
            # innovation y - C xhat - D
            innovation = y - C @ x - self.D
            CP = C @ P
            # R + mu C P C^T
            RmuCPC = self.R + mu * (CP @ C.T)
            # W = (R + mu C P C^T)^-1 C P, shared by K, P^Delta and the corrected estimate
            W = np.linalg.solve(RmuCPC, CP)
            if self.transition == 'euler':
                I_muA_P = I_muA @ P
                # K = (I + mu A) P C^T (R + mu C P C^T)^-1 = (I + mu A) W^T
                K = I_muA @ W.T
                # xhat^Delta = A xhat + B u + K [y - C xhat - D]
                x_delta = A @ x + self.B @ u + K @ innovation
                # P^Delta = AP + (I+muA) P A^T + GQG^T - (I+muA) P C^T (R+muCPC^T)^-1 C P (I+muA^T)
                P_delta = A @ P + I_muA_P @ A.T + self.GQGt - K @ CP @ I_muA.T
                # f(sigma) = f + mu f^Delta
                x_new = x + mu * x_delta
                P_new = P + mu * P_delta
            # corrected estimate at t: measurement update with R_d = R / mu;
            # S = C P C^T + R / mu = (R + mu C P C^T) / mu, so L = P C^T S^-1 = mu W^T
            Rd = self.R / mu
            S = RmuCPC / mu
            L = mu * W.T
            x_c = x + L @ innovation
            # Joseph form keeps P(t|t) symmetric positive semi-definite in floating point
            I_LC = eye - L @ C
            P_c = I_LC @ P @ I_LC.T + L @ Rd @ L.T
            if self.transition == 'exact':
                x_new = F @ x_c + Bd @ u
                P_new = F @ P_c @ F.T + Qd
        P_new = (P_new + P_new.T) / 2
        if not (np.isfinite(x_new).all() and np.isfinite(P_new).all()):
            raise FilterError(f'step with mu = {mu} overflowed; the filter state is unchanged')
        self.x, self.P = x_new, P_new
        self.x_corrected, self.P_corrected = x_c, P_c
        return StepResult(mu, x_c, P_c, x_new, P_new, innovation, S)

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
