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
The search for the maximum of the innovation likelihood over log diag(Q), log diag(R).

`noise_fit.fit` maximises log L(Q, R); here are its parts that do not depend on what the
likelihood is: the parameters (`NoiseParameters`), the coarse start (`coarse_start`,
`data_scale`), the bounded search (`search`) and the Hessian of the standard errors
(`numerical_hessian`).

The stopping rule is the likelihood's own scale.  Near the maximum theta^ of log L with
standard errors from the inverse Hessian, a point z standard errors away (in the
Mahalanobis sense) is log L(theta^) - log L(theta) = z^2 / 2 lower: a gap of 0.5 is one
standard error.  The search stops when an iteration improves log L by less than
LOG_L_TOLERANCE = 1e-3 (z = 0.045): far below the estimate's own uncertainty.  How:
doc/design/core.md.
"""

from dataclasses import dataclass
from typing import Callable, Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
import scipy.optimize

from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.spill_rows import SpillRows
from tskf_ros.core.step_columns import StepRecord
from tskf_ros.core.streamed_median import median

FloatArray = NDArray[np.float64]

# how far (in natural-log units) the optimiser may move a parameter from its start
LOG_SEARCH_RADIUS = 25.0
# central-difference step of the Hessian, in log-parameters (a 1% change of q or r)
HESSIAN_STEP = 1e-2
# a parameter within this of its search bound has run to the bound
AT_BOUND = 1e-3
# a parameter that ends at its bound is searched again around there, at most this often
# (so up to e^(+-25 x 4) from the start: a start far from the data's scale is found)
RECENTRES = 3
# the coarse search before the optimiser: these offsets of each log-parameter (e^-12..e^6)
COARSE_OFFSETS = (-12.0, -9.0, -6.0, -3.0, 0.0, 3.0, 6.0)
# and these around the data's own scale (data_scale: all the spread on Q, or all on R)
DATA_OFFSETS = (-9.0, -6.0, -3.0, 0.0, 3.0)
# the search stops when an iteration improves log L by less than this, and the fit ends
# if the quadratic model at that point puts the maximum less than this above it (a point
# z standard errors from the maximum is z^2 / 2 below it: 1e-3 is z = 0.045)
LOG_L_TOLERANCE = 1e-3
# the coarse search compares its points over the first this many measurement steps
COARSE_STEPS = 16384

# the log-likelihood as a function of the log-parameters theta
Objective = Callable[[FloatArray], float]
# told (evaluations so far, the best log-likelihood so far) after each evaluation
FitProgress = Callable[[int, float], None]


@dataclass(frozen=True)
class NoiseParameters:
    """Which entries are fitted: the diagonals of Q (r x r) and R (p x p), as logs."""

    r: int
    p: int
    fit_Q: bool = True
    fit_R: bool = True

    @property
    def names(self) -> list[str]:
        """Return the parameter names, e.g. ['Q[0,0]', 'R[0,0]']."""
        out = [f'Q[{i},{i}]' for i in range(self.r)] if self.fit_Q else []
        return out + ([f'R[{i},{i}]' for i in range(self.p)] if self.fit_R else [])

    def start(self, Q: FloatArray, R: FloatArray) -> FloatArray:
        """Return the log-parameters of Q and R (a non-positive diagonal entry starts at 1)."""
        diag: list[float] = []
        if self.fit_Q:
            diag += list(np.diag(Q))
        if self.fit_R:
            diag += list(np.diag(R))
        return np.log(np.where(np.asarray(diag) > 0, diag, 1.0))

    def matrices(self, theta: ArrayLike, Q: ArrayLike, R: ArrayLike
                 ) -> tuple[FloatArray, FloatArray]:
        """Return (Q, R) for the log-parameters theta (entries not fitted: from Q, R)."""
        theta = np.asarray(theta, dtype=float)
        k = 0
        if self.fit_Q:
            Q = np.diag(np.exp(theta[:self.r]))
            k = self.r
        if self.fit_R:
            R = np.diag(np.exp(theta[k:k + self.p]))
        return np.asarray(Q, dtype=float), np.asarray(R, dtype=float)

    def stderr_matrices(self, theta: ArrayLike, se_log: ArrayLike
                        ) -> tuple[FloatArray, FloatArray]:
        """Delta method: se(q) = q se(log q) on the fitted diagonals, 0 elsewhere."""
        se = np.exp(np.asarray(theta, dtype=float)) * np.asarray(se_log, dtype=float)
        Qs, Rs = np.zeros((self.r, self.r)), np.zeros((self.p, self.p))
        k = 0
        if self.fit_Q:
            Qs[np.diag_indices(self.r)] = se[:self.r]
            k = self.r
        if self.fit_R:
            Rs[np.diag_indices(self.p)] = se[k:k + self.p]
        return Qs, Rs


def numerical_hessian(f: Objective, x: ArrayLike, h: float = HESSIAN_STEP) -> FloatArray:
    """Central-difference Hessian of f at x with step h in every coordinate."""
    x = np.asarray(x, dtype=float)
    n = x.size
    H = np.zeros((n, n))
    f0 = f(x)
    step = np.eye(n) * h
    for i in range(n):
        H[i, i] = (f(x + step[i]) - 2.0 * f0 + f(x - step[i])) / (h * h)
        for j in range(i):
            H[i, j] = H[j, i] = (f(x + step[i] + step[j]) - f(x + step[i] - step[j])
                                 - f(x - step[i] + step[j]) + f(x - step[i] - step[j])
                                 ) / (4.0 * h * h)
    return H


def coarse_start(f: Objective, theta0: ArrayLike,
                 offsets: Sequence[float] = COARSE_OFFSETS) -> tuple[FloatArray, float]:
    """
    Return the best point of a coarse search around theta0 and its value.

    The likelihood can have a valley that runs to a bound (at 1 kHz, model (3) with Q near
    the paper's 1 improves as R -> 0), where a gradient method started at the file's
    values ends.  So each log-parameter is first tried at theta0 + offsets: the full
    grid for up to two parameters, one coordinate at a time (keeping the best) for more.
    """
    theta0 = np.asarray(theta0, dtype=float)
    steps = np.asarray(offsets, dtype=float)
    if theta0.size <= 2:
        grid = [theta0 + np.array(c) for c in _product(steps, theta0.size)]
        values = [f(t) for t in grid]
        i = int(np.argmin(values))
        return grid[i], float(values[i])
    best, best_value = theta0.copy(), f(theta0)
    for i in range(theta0.size):
        for d in steps:
            t = best.copy()
            t[i] = theta0[i] + d
            v = f(t)
            if v < best_value:
                best, best_value = t, v
    return best, float(best_value)


def data_scale(model: LinearModel, segments: Sequence[Sequence[StepRecord]],
               par: NoiseParameters, theta0: FloatArray) -> FloatArray:
    """
    Return log-parameters at the data's own scale (theta0 where the data say nothing).

    From the differences of successive measurements, dy over dt: their robust variance
    v_i = median(dy_i^2) / 0.455 (the median of chi2(1)) put all on the measurement noise,
    R_ii = v_i dt / 2 (R / mu per sample, twice per difference), or all on the process
    noise, Q_jj = mean(v) / (dt |(C G)_j|^2), with dt the median spacing.
    """
    p = model.C.shape[0]
    with SpillRows(np.dtype((np.float64, (p,)))) as dys, SpillRows(np.float64) as dts:
        return _data_scale(model, segments, par, theta0, dys, dts)


def _data_scale(model: LinearModel, segments: Sequence[Sequence[StepRecord]],
                par: NoiseParameters, theta0: FloatArray, dys: SpillRows, dts: SpillRows
                ) -> FloatArray:
    """data_scale with the differences kept in dys and dts (temporary files)."""
    p = model.C.shape[0]
    for segment in segments:
        t, last = 0.0, None
        for rec in segment:
            if rec.y is not None:
                y = np.asarray(rec.y, dtype=float).reshape(-1)
                if last is not None and t > last[0]:
                    dys.append(y - last[1])
                    dts.append(t - last[0])
                last = (t, y)
            t += rec.mu
    theta = np.array(theta0, dtype=float)
    if len(dys) < 2:
        return theta
    with np.errstate(all='ignore'):
        # np.median(np.square(dys), axis=0), np.median(dts): a block of rows at a time
        v = np.array([median(_column_squared(dys, i)) for i in range(p)]) / 0.455
        dt = float(median(dts.blocks))
        G = model.G if model.G is not None else np.eye(model.A.shape[0])
        cg = np.sum(np.square(model.C @ G), axis=0)
        k = 0
        if par.fit_Q:
            q = np.mean(v) / (dt * cg)
            theta[:par.r] = np.where(np.isfinite(q) & (q > 0), np.log(q), theta[:par.r])
            k = par.r
        if par.fit_R:
            r = v * dt / 2.0
            theta[k:k + par.p] = np.where(np.isfinite(r) & (r > 0), np.log(r),
                                          theta[k:k + par.p])
    return theta


def _column_squared(rows: SpillRows, i: int) -> Callable[[], Iterator[FloatArray]]:
    """Return blocks(): the squares of column i of rows, a block at a time."""
    return lambda: (np.square(block[:, i]) for block in rows.blocks())


def _product(offsets: FloatArray, k: int) -> list[list[float]]:
    """Return every k-tuple of offsets."""
    grids = np.meshgrid(*([offsets] * k), indexing='ij')
    return np.stack([g.ravel() for g in grids], axis=1).tolist()


def search(f: Objective, start: FloatArray, centre: FloatArray, strict: bool = False
           ) -> tuple[FloatArray, FloatArray, FloatArray, str, bool]:
    """
    Minimise f from start within centre +- LOG_SEARCH_RADIUS (L-BFGS-B, then Nelder-Mead).

    f is -log L.  Both stop when an iteration improves it by less than LOG_L_TOLERANCE
    (L-BFGS-B's ftol is relative to |f|: it is scaled by f at the start), or, strict, by
    less than 1e-13 |f| (a projected gradient below 1e-7; Nelder-Mead: 1e-9, its simplex
    1e-6 wide).  Nelder-Mead is tried only if L-BFGS-B does not converge.  Return (theta,
    lower bounds, upper bounds, the optimiser's message, success).
    """
    lo, hi = centre - LOG_SEARCH_RADIUS, centre + LOG_SEARCH_RADIUS
    bounds = list(zip(lo, hi))
    start = np.clip(start, lo, hi)
    ftol = 1e-13 if strict else LOG_L_TOLERANCE / max(abs(f(start)), 1.0)
    res = scipy.optimize.minimize(f, start, method='L-BFGS-B', bounds=bounds,
                                  options={'maxiter': 500, 'ftol': ftol, 'gtol': 1e-7})
    theta, message, success = res.x, str(res.message), bool(res.success)
    if not success:
        nm = scipy.optimize.minimize(f, theta, method='Nelder-Mead', bounds=bounds,
                                     options={'xatol': 1e-6, 'maxiter': 2000,
                                              'fatol': 1e-9 if strict else LOG_L_TOLERANCE})
        if nm.fun <= res.fun:
            theta, success = nm.x, bool(nm.success)
            message = f'L-BFGS-B: {res.message}; Nelder-Mead: {nm.message}'
    return np.asarray(theta, dtype=float), lo, hi, message, success


def newton_gap(f: Objective, x: ArrayLike, H: FloatArray, h: float = HESSIAN_STEP) -> float:
    """
    Return how far below its maximum the quadratic model puts x: g^T H^-1 g / 2.

    f is -log L, H its Hessian at x (numerical_hessian's), g its central-difference
    gradient with the same step (the same points: no new evaluation if f keeps its
    values).  inf if H is not positive definite (no maximum of the model nearby).
    """
    x = np.asarray(x, dtype=float)
    step = np.eye(x.size) * h
    g = np.array([(f(x + step[i]) - f(x - step[i])) / (2.0 * h) for i in range(x.size)])
    try:
        L = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return float('inf')
    z = np.linalg.solve(L, g)
    gap = 0.5 * float(z @ z)
    return gap if np.isfinite(gap) else float('inf')
