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

import math
from typing import Callable, Optional, overload, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core import kalman, kalman_bucy
from tskf_ros.core.filter_results import InnovationTest, RunResult, StepResult
from tskf_ros.core.kalman_bucy import KalmanBucyModel
from tskf_ros.core.matrices import as_matrix, as_vector, check_covariance, FilterError
from tskf_ros.core.transitions import (noise_over, Transition, TransitionCache,
                                       TRANSITIONS, Transitions)

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['FilterError', 'InnovationTest', 'NonRegressiveError', 'RunResult', 'StepResult',
           'TimeScaleKalmanFilter', 'TRANSITIONS']

_INF = math.inf


class NonRegressiveError(FilterError):
    """A step whose I + mu A is singular (Definition 2.12): refused, the state is sound."""


class _ModelMatrix:
    """A model-matrix attribute: assigning it is checked and re-derives the caches."""

    def __init__(self, name: str) -> None:
        self.name, self.private = name, '_' + name
        self.__doc__ = f'The model matrix {name} (assigning it is checked).'

    @overload
    def __get__(self, obj: None, owner: type['TimeScaleKalmanFilter']) -> '_ModelMatrix':
        ...

    @overload
    def __get__(self, obj: 'TimeScaleKalmanFilter', owner: type['TimeScaleKalmanFilter']
                ) -> Matrix:
        ...

    def __get__(self, obj: Optional['TimeScaleKalmanFilter'], owner: type['TimeScaleKalmanFilter']
                ) -> Union['_ModelMatrix', Matrix]:
        if obj is None:
            return self
        matrix: Matrix = getattr(obj, self.private)
        return matrix

    def __set__(self, obj: 'TimeScaleKalmanFilter', value: ArrayLike) -> None:
        name = self.name
        old = getattr(obj, self.private)
        new = as_matrix(value, name, column=name in ('G', 'B'))
        if name == 'D':
            new = new.reshape(-1)
        if new.shape != old.shape:
            raise FilterError(f'{name} must keep its shape {old.shape}, got {new.shape}')
        if name in ('Q', 'R'):
            new = check_covariance(new, name, definite=name == 'R')
        setattr(obj, self.private, new)
        obj._prepare()


class TimeScaleKalmanFilter:
    """
    Kalman filter on a time scale: Bohner & Wintz Table 3 with Cai's offset D.

    After construction `x`, `P` hold the estimate at the first point t0.  Each
    `step(mu, y)` uses the measurement at the current point t and moves `x`, `P`
    to sigma(t) = t + mu (the paper's predictor), and keeps the corrected
    estimate at t in `x_corrected`, `P_corrected`.  The model is checked once, here;
    the model matrices can be assigned later (checked, same shape).
    """

    A = _ModelMatrix('A')
    C = _ModelMatrix('C')
    G = _ModelMatrix('G')
    Q = _ModelMatrix('Q')
    R = _ModelMatrix('R')
    B = _ModelMatrix('B')
    D = _ModelMatrix('D')

    def __init__(self, A: ArrayLike, C: ArrayLike, *, Q: ArrayLike, R: ArrayLike,
                 G: Optional[ArrayLike] = None, B: Optional[ArrayLike] = None,
                 D: Optional[ArrayLike] = None, x0: ArrayLike, P0: ArrayLike,
                 transition: str = 'euler', allow_nonregressive: bool = False) -> None:
        A_ = as_matrix(A, 'A')
        n = A_.shape[0]
        if A_.shape != (n, n):
            raise FilterError(f'A must be square, got shape {A_.shape}')
        C_ = as_matrix(C, 'C')
        if C_.shape[1] != n:
            raise FilterError(f'C must have {n} columns to match A {A_.shape}, '
                              f'got shape {C_.shape}')
        p = C_.shape[0]
        G_ = np.eye(n) if G is None else as_matrix(G, 'G', column=True)
        if G_.shape[0] != n:
            raise FilterError(f'G must have {n} rows to match A, got shape {G_.shape}')
        r = G_.shape[1]
        Q_ = check_covariance(as_matrix(Q, 'Q'), 'Q')
        if Q_.shape != (r, r):
            raise FilterError(f'Q must have shape {(r, r)} to match G {G_.shape}, '
                              f'got {Q_.shape}')
        R_ = check_covariance(as_matrix(R, 'R'), 'R', definite=True)
        if R_.shape != (p, p):
            raise FilterError(f'R must have shape {(p, p)} to match C {C_.shape}, '
                              f'got {R_.shape}')
        if B is None:
            B_ = np.zeros((n, 1))
        else:
            B_ = as_matrix(B, 'B', column=True)
            if B_.shape[0] != n:
                raise FilterError(f'B must have {n} rows, got shape {B_.shape}')
        D_ = np.zeros(p) if D is None else as_matrix(D, 'D').reshape(-1)
        if D_.shape != (p,):
            raise FilterError(f'D must have {p} entries to match C, got {D_.size}')
        if transition not in TRANSITIONS:
            raise FilterError(f'transition must be one of {TRANSITIONS}, got {transition!r}')
        self._A, self._C, self._G, self._Q, self._R, self._B, self._D = \
            A_, C_, G_, Q_, R_, B_, D_
        self._transition = transition
        # Definition 2.12 asks I + mu A to be invertible; Table 3 itself never inverts it,
        # so a user who knowingly runs a non-regressive model (as Cai et al. do with
        # system (1) at mu = 1) can say so.  Off by default: such a step is refused.
        self.allow_nonregressive = bool(allow_nonregressive)
        self._prepare()
        self.x: Vector = as_vector(x0, n, 'x0').copy()
        P0m = as_matrix(P0, 'P0')
        if P0m.shape != (n, n):
            raise FilterError(f'P0 must have shape {(n, n)}, got {P0m.shape}')
        self.P: Matrix = check_covariance(P0m, 'P0')
        self.x_corrected: Optional[Vector] = None
        self.P_corrected: Optional[Matrix] = None

    def _prepare(self) -> None:
        """Derive what every step reuses from the (checked) model matrices."""
        self.GQGt = self._G @ self._Q @ self._G.T
        self._zero = np.zeros(self.n)
        # the shapes of a step's x(t|t), P(t|t), x(sigma), P(sigma), e, S (new arrays each step)
        n, p = self.n, self.p
        self._shapes = ((n,), (n, n), (p,), (p, p))
        self._uses_B = bool(np.any(self._B))
        self._jumps = TransitionCache(self._transition, self._A, self.GQGt, self._B,
                                      input_matrix=self._uses_B)
        # R_d of the last mu stepped with the model's R (exact stamps: the same every step)
        self._Rd_mu, self._Rd = 0.0, self._R

    @property
    def transition(self) -> str:
        """'euler' (the paper's I + mu A) or 'exact' (e^{A mu}); assigning it is checked."""
        return self._transition

    @transition.setter
    def transition(self, value: str) -> None:
        if value not in TRANSITIONS:
            raise FilterError(f'transition must be one of {TRANSITIONS}, got {value!r}')
        self._transition = value
        self._prepare()

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self._A.shape[0])

    @property
    def p(self) -> int:
        """Measurement dimension."""
        return int(self._C.shape[0])

    def _input(self, u: Optional[ArrayLike]) -> Vector:
        if u is None:
            return np.zeros(self._B.shape[1])
        return as_vector(u, self._B.shape[1], 'u')

    def transition_matrices(self, mu: float) -> tuple[Matrix, Matrix, Matrix]:
        """Return (F, Q_d, B_d) for a jump of mu: Euler (I + mu A) or the exact sampled plant."""
        jump = self._jumps[mu]
        return jump.F, jump.Qd, jump.Bd

    def transition_stack(self, mus: NDArray[np.float64]) -> Transitions:
        """Return the transitions (F, Q_d, B_d, regressive) of every mu of mus, stacked."""
        return self._jumps.stack(mus)

    def _jump(self, mu: float) -> Transition:
        """Return the transition over mu; raise NonRegressiveError where Definition 2.12 fails."""
        jump = self._jumps[mu]
        self._check_regressive(jump.regressive, mu)
        return jump

    def _check_regressive(self, regressive: bool, mu: float) -> None:
        """Raise NonRegressiveError if I + mu A is singular and that is not allowed."""
        if not regressive and not self.allow_nonregressive:
            raise NonRegressiveError(
                f'I + mu A is singular at mu = {mu}: A is not regressive on this time '
                'scale (Bohner & Wintz Definition 2.12); the step is refused')

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

    def _measurement_noise(self, R: ArrayLike) -> Matrix:
        """R for one step: a variance > 0 (R I) or a p x p positive definite matrix."""
        if isinstance(R, (float, int)) and not isinstance(R, bool):
            r = float(R)
            if not (0.0 < r < _INF):
                raise FilterError(f'R must be a finite variance > 0, got {r}')
            return np.eye(self.p) * r
        R_ = check_covariance(as_matrix(R, 'R'), 'R', definite=True)
        if R_.shape != (self.p, self.p):
            raise FilterError(f'R must have shape {(self.p, self.p)}, got {R_.shape}')
        return R_

    @staticmethod
    def _noise_over(mu: Union[float, NDArray[np.float64]], R: Matrix) -> NDArray[np.float64]:
        """R_d = R / mu (transitions.noise_over's source, numpy broadcasting a stack of mu)."""
        return noise_over.py_func(R, mu)

    def _model_noise_over(self, mu: float) -> Matrix:
        """Return R_d = R / mu of the model's R (kept for the next step with the same mu)."""
        if mu != self._Rd_mu:
            self._Rd_mu, self._Rd = mu, self._noise_over(mu, self._R)
        return self._Rd

    def step(self, mu: float, y: Optional[ArrayLike], u: Optional[ArrayLike] = None, *,
             R: Optional[ArrayLike] = None) -> StepResult:
        """
        Advance from t to sigma(t) = t + mu with the measurement y(t) (Table 3).

        `y=None` is an explicit missing measurement: only the time update is made
        (K = 0), which is what Table 3 gives as R -> infinity.  `R` replaces the model's
        R for this step only (a variance: R I, or a p x p matrix), as FilterPy's
        `update(z, R=...)`.

        The step is the update with R_d = R / mu followed by the prediction with
        F, Q_d, B_d of the transition (tskf_ros.core.kalman): Table 3's algebra, since
        (I + mu A) W^T = K with W = (R + mu C P C^T)^-1 C P gives
        P + mu P^Delta = F (P - mu P C^T W) F^T + mu GQG^T and
        xhat + mu xhat^Delta = F (xhat + mu W^T e) + mu B u.
        """
        mu = self.check_mu(mu)
        uses_u = u is not None and self._uses_B
        if y is not None and not uses_u and self._jumps.once(mu):
            # a mu met for the first time (jittered stamps): its jump and the step in one
            # compiled call, the jump not kept
            step, regressive = self._jumps.step_once(
                self.x, self.P, as_vector(y, self.p, 'y'), self._C,
                self._R if R is None else self._measurement_noise(R), self._D, mu)
            self._check_regressive(regressive, mu)
            return self._keep(mu, step)
        jump = self._jump(mu)
        Bu = self._zero
        if u is not None and self._uses_B:
            Bu = jump.Bd @ as_vector(u, self._B.shape[1], 'u')
        if y is None:
            x_p, P_p = kalman.predict(self.x, self.P, jump.F, jump.Qd, Bu)
            if not kalman.finite(x_p, P_p):
                raise FilterError(f'step with mu = {mu} overflowed; '
                                  'the filter state is unchanged')
            nan = np.full(self.p, np.nan)
            res = StepResult(mu, self.x, self.P, x_p, P_p, nan, np.full((self.p,) * 2, np.nan))
        else:
            z = as_vector(y, self._C.shape[0], 'y')
            Rd = (self._model_noise_over(mu) if R is None
                  else self._noise_over(mu, self._measurement_noise(R)))
            # written into new arrays (a step's arrays are kept: the session's history)
            n1, nn, p1, pp = self._shapes
            new = np.empty
            out = (new(n1), new(nn), new(n1), new(nn), new(p1), new(pp))
            return self._keep(mu, out + (kalman.update_predict_into(
                self.x, self.P, z, self._C, Rd, self._D, jump.F, jump.Qd, Bu, *out),))
        self.x, self.P = res.x_predicted, res.P_predicted
        self.x_corrected, self.P_corrected = res.x_corrected, res.P_corrected
        return res

    def _keep(self, mu: float, step: tuple) -> StepResult:
        """Keep kalman.update_predict's step as the filter's state, or raise why not."""
        x_c, P_c, x_p, P_p, e, S, status = step
        if status == kalman.NOT_POSITIVE:
            raise FilterError(f'R + mu C P C^T is not positive at mu = {mu}: '
                              'P has lost semi-definiteness')
        if status == kalman.NOT_FINITE:
            raise FilterError(f'step with mu = {mu} overflowed; '
                              'the filter state is unchanged')
        self.x, self.P = x_p, P_p
        self.x_corrected, self.P_corrected = x_c, P_c
        return StepResult(mu, x_c, P_c, x_p, P_p, e, S)

    def run(self, mu: ArrayLike, y: ArrayLike, u: Optional[ArrayLike] = None, *,
            test: Optional[InnovationTest] = None, innovations: bool = False) -> RunResult:
        """
        Make step(mu[k], y[k], u) for k = 0, 1, ... in one compiled call (kalman's run).

        The steps and their results are those of the loop over `step`; it stops before a
        step that `step` would refuse (that step raises there, saying why), or, with a
        test, before keeping a step whose prediction fails it.  x, P are left at the
        prediction of the last step kept.  innovations: also give each step's innovation
        e and its covariance S (`step`'s), from the steps' priors in one call of
        kalman.innovation_runs.
        """
        mus = np.asarray(mu, dtype=float).reshape(-1)
        K, p = mus.size, self.p
        z = np.asarray(y, dtype=float).reshape(K, p)
        bad = ~((mus > 0.0) & (mus < _INF)) | ~np.isfinite(z).all(axis=1)
        values, jump = np.unique(mus, return_inverse=True)
        # the transitions of the run's distinct mu in one call (a mu that is not a
        # graininess gets mu = 1, never used: the run stops at the step before it)
        jumps = self._jumps.stack(np.where((values > 0.0) & (values < _INF), values, 1.0))
        if not self.allow_nonregressive:
            bad |= ~jumps.regressive[jump]
        if u is not None and self._uses_B:
            uv = as_vector(u, self._B.shape[1], 'u')
            Bu = np.array([Bd @ uv for Bd in jumps.Bd])     # as `step` makes B_d u
        else:
            Bu = np.zeros((values.size, self.n))
        limit = int(np.argmax(bad)) if bad.any() else K
        if test is None:
            z_test, R_test, limit2 = z, self._R, -1.0
        else:
            z_test, R_test, limit2 = test.z, test.R, float(test.limit2)
        x0, P0 = self.x, self.P
        Rd = self._noise_over(mus[:limit, None, None], self._R)
        x_c, P_c, x_p, P_p, count, status = kalman.update_predict_run(
            x0, P0, z[:limit], self._C, Rd,
            self._D, jumps.F, jumps.Qd, Bu, jump[:limit].astype(np.intp),
            np.asarray(z_test, dtype=float), R_test, limit2)
        if count:
            self.x, self.P = x_p[count - 1], P_p[count - 1]
            self.x_corrected, self.P_corrected = x_c[count - 1], P_c[count - 1]
        stopped = '' if count == K else 'test' if status == kalman.STOPPED else 'refused'
        if not innovations:
            return RunResult(count, x_c, P_c, x_p, P_p, stopped)
        if not count:
            return RunResult(count, x_c, P_c, x_p, P_p, stopped, np.empty((0, self.p)),
                             np.empty((0, self.p, self.p)))
        # step k's prior is step k-1's prediction (the run's first: the filter's state)
        e, S, _ = kalman.innovation_runs(np.concatenate([x0[None], x_p[:count - 1]]),
                                         np.concatenate([P0[None], P_p[:count - 1]]),
                                         z[:count], self._C[None], Rd[:count], self._D[None])
        return RunResult(count, x_c, P_c, x_p, P_p, stopped, e, S)

    def integrate(self, duration: float, y: Callable[[float], ArrayLike],
                  u: Optional[Callable[[float], ArrayLike]] = None, *,
                  rtol: float = 1e-9, atol: float = 1e-12) -> None:
        """
        Run the Kalman-Bucy filter (Table 2) over a right-dense stretch [t, t + duration].

        y(s) and u(s) give the continuous measurement and input at s in [0, duration]
        (time from the start of the stretch); `kalman_bucy.integrate` solves the ODEs
        of xhat and P together (scipy's RK45, rtol and atol).
        """
        duration = float(duration)
        if not np.isfinite(duration) or duration < 0:
            raise FilterError(f'duration must be finite and >= 0, got {duration}')
        if duration == 0:
            return
        model = KalmanBucyModel(self.A, self.B, self.C, self.D, self.GQGt, self.R)
        self.x, self.P = kalman_bucy.integrate(
            model, self.x, self.P, duration, y,
            lambda s: self._input(None if u is None else u(s)), rtol=rtol, atol=atol)

    def state(self) -> tuple[Vector, Matrix]:
        """Return a copy of (x, P), for history and rewinding."""
        return self.x.copy(), self.P.copy()

    def set_state(self, x: ArrayLike, P: ArrayLike) -> None:
        """Restore an estimate and covariance (checked)."""
        x = as_vector(x, self.n, 'x').copy()
        P = check_covariance(as_matrix(P, 'P', (self.n, self.n)), 'P')
        self.x, self.P = x, P
