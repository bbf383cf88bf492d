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
Maximum likelihood of the noise intensities Q and R from the time-scale filter's innovations.

The prediction-error decomposition over the steps with a measurement, with the innovations
e_k = y_k - C xhat_k - D and S_k = C P_k C^T + R / mu_k of Bohner & Wintz Table 3:

    log L(Q, R) = -1/2 sum_k [ log det S_k + e_k^T S_k^-1 e_k + p log 2 pi ]

maximised over log diag(Q) and log diag(R); standard errors se(q) = q se(log q) (delta
method) from the Hessian in the log-parameters.  How:
doc/design/core.md.
"""

from dataclasses import dataclass, field, replace
from typing import Callable, Iterator, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
import scipy.optimize

from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.pairwise_sum import PairwiseSum
from tskf_ros.core.spill_rows import SpillRows
from tskf_ros.core.streamed_median import median
from tskf_ros.core.timescale_kalman import FilterError, TimeScaleKalmanFilter

LOG_2PI = float(np.log(2.0 * np.pi))
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

FloatArray = NDArray[np.float64]
# the log-likelihood as a function of the log-parameters theta
Objective = Callable[[FloatArray], float]
# told (evaluations so far, the best log-likelihood so far) after each evaluation
FitProgress = Callable[[int, float], None]


@dataclass(frozen=True)
class StepRecord:
    """One step of the filter: mu (s), y (None: an input-only point) and the input u."""

    mu: float
    y: Optional[FloatArray]
    u: Optional[FloatArray] = None
    variance: float = 0.0       # the sample's own R_d (use_message_variance), 0: R / mu


@dataclass
class Innovations:
    """Innovations e_k (N x p), their covariances S_k (N x p x p) and NIS_k (N)."""

    e: FloatArray
    S: FloatArray
    nis: FloatArray
    log_det_S: FloatArray

    @property
    def count(self) -> int:
        """Return the number of measurement steps N."""
        return int(self.nis.size)

    def log_likelihood(self) -> float:
        """Return log L = -1/2 sum [log det S + e^T S^-1 e + p log 2 pi]."""
        p = self.e.shape[1] if self.e.ndim == 2 else 1
        return log_likelihood_of(np.sum(self.log_det_S), np.sum(self.nis), self.count, p)


def log_likelihood_of(sum_log_det: float, sum_nis: float, count: int, p: int) -> float:
    """Return log L = -1/2 [sum log det S_k + sum NIS_k + N p log 2 pi] from the sums."""
    return -0.5 * float(sum_log_det + sum_nis + count * p * LOG_2PI)


def innovation_terms(e: FloatArray, S: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return (NIS_k = e^T S^-1 e, log det S_k) through a Cholesky factor of each S_k."""
    e = np.asarray(e, dtype=float).reshape(len(S), -1)
    L = np.linalg.cholesky(np.asarray(S, dtype=float))
    z = np.linalg.solve(L, e[..., None])[..., 0]
    return np.sum(z * z, axis=1), 2.0 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2)), axis=1)


def with_noise(model: LinearModel, Q: ArrayLike, R: ArrayLike) -> LinearModel:
    """Return the model with Q and R replaced."""
    return replace(model, Q=np.asarray(Q, dtype=float), R=np.asarray(R, dtype=float))


# measurement steps whose innovations are made at a time
TRACE_BLOCK = 4096


class _Rows:
    """Innovation rows gathered into blocks of a fixed size (innovation_blocks' buffer)."""

    def __init__(self, block: int, p: int) -> None:
        self.e, self.S, self.k = np.empty((block, p)), np.empty((block, p, p)), 0

    def add(self, e: FloatArray, S: FloatArray) -> Iterator[tuple[FloatArray, FloatArray]]:
        """Append rows; yield (copies of) each block they fill."""
        block, i = len(self.e), 0
        while i < len(e):
            take = min(len(e) - i, block - self.k)
            self.e[self.k:self.k + take], self.S[self.k:self.k + take] = \
                e[i:i + take], S[i:i + take]
            self.k, i = self.k + take, i + take
            if self.k == block:
                yield self.e.copy(), self.S.copy()
                self.k = 0

    def rest(self) -> Iterator[tuple[FloatArray, FloatArray]]:
        """Yield the last rows, a block not full."""
        if self.k:
            yield self.e[:self.k].copy(), self.S[:self.k].copy()


def _run(kf: TimeScaleKalmanFilter, mus: list, ys: list) -> tuple[FloatArray, FloatArray]:
    """Make the steps in one compiled run; return their (e_k, S_k) (those of `step`)."""
    res = kf.run(mus, np.array(ys), innovations=True)
    e, S = res.innovation, res.S
    assert e is not None and S is not None     # asked for
    if res.steps == len(mus):
        return e, S
    # the run stopped before a step `step` refuses: made by `step`, which raises saying why
    rest = [kf.step(mu, y) for mu, y in zip(mus[res.steps:], ys[res.steps:])]
    return (np.concatenate([e, [r.innovation for r in rest]]),
            np.concatenate([S, [r.S for r in rest]]))


def innovation_blocks(model: LinearModel, transition: str,
                      segments: Sequence[Sequence[StepRecord]], block: int = TRACE_BLOCK
                      ) -> Iterator[tuple[FloatArray, FloatArray]]:
    """
    Run the core filter over the trace; yield (e_k, S_k) of measurement steps in blocks.

    Each segment starts from a fresh filter (x0, P0).  A step with a sample variance
    (use_message_variance) is run with R = variance * mu, so that R / mu is that variance,
    as the estimator session does.  Runs of measurement steps with the model's R and no
    input are made in one compiled call each (`TimeScaleKalmanFilter.run`, the same
    steps as `step`'s), the other steps one at a time.  Raises FilterError if a step
    fails.  At most `block` steps are kept at a time: a trace of any length runs in
    bounded memory.
    """
    rows = _Rows(block, model.C.shape[0])
    for segment in segments:
        kf = model.make_filter(transition, allow_nonregressive=True)
        R_model = kf.R
        mus: list = []
        ys: list = []
        for rec in segment:
            plain = rec.u is None or model.B is None     # no input the model takes
            if rec.y is not None and not rec.variance > 0 and plain:
                mus.append(rec.mu)
                ys.append(rec.y)
                if len(mus) == block:
                    yield from rows.add(*_run(kf, mus, ys))
                    mus, ys = [], []
                continue
            if mus:
                yield from rows.add(*_run(kf, mus, ys))
                mus, ys = [], []
            if rec.y is not None and rec.variance > 0:
                kf.R = np.eye(kf.p) * rec.variance * rec.mu
                try:
                    res = kf.step(rec.mu, rec.y, rec.u)
                finally:
                    kf.R = R_model
            else:
                res = kf.step(rec.mu, rec.y, rec.u)
            if rec.y is not None:
                yield from rows.add(res.innovation[None], res.S[None])
        if mus:
            yield from rows.add(*_run(kf, mus, ys))
    yield from rows.rest()


def run_trace(model: LinearModel, transition: str, segments: Sequence[Sequence[StepRecord]]
              ) -> Innovations:
    """Run the core filter's step over the trace (innovation_blocks); return the innovations."""
    p = model.C.shape[0]
    blocks = list(innovation_blocks(model, transition, segments))
    if not blocks:
        return Innovations(np.zeros((0, p)), np.zeros((0, p, p)), np.zeros(0), np.zeros(0))
    e = np.concatenate([b[0] for b in blocks])
    S = np.concatenate([b[1] for b in blocks])
    nis, log_det = innovation_terms(e, S)
    return Innovations(e, S, nis, log_det)


def measurement_steps(segments: Sequence[Sequence[StepRecord]]) -> int:
    """Return the number of steps with a measurement (a trace's own count, if it keeps one)."""
    count = getattr(segments, 'measurement_steps', None)
    if count is not None:
        return int(count)
    return sum(rec.y is not None for segment in segments for rec in segment)


def trace_log_likelihood(model: LinearModel, transition: str,
                         segments: Sequence[Sequence[StepRecord]]) -> float:
    """
    Return log L of the trace (run_trace(...).log_likelihood()) in bounded memory.

    The NIS and log det S of each block of innovations are added up as np.sum adds the
    whole columns (PairwiseSum): the same number, bit for bit, without keeping them.
    """
    n = measurement_steps(segments)
    sum_nis, sum_log_det = PairwiseSum(n), PairwiseSum(n)
    p = model.C.shape[0]
    for e, S in innovation_blocks(model, transition, segments):
        nis, log_det = innovation_terms(e, S)
        sum_nis.add(nis)
        sum_log_det.add(log_det)
    return log_likelihood_of(sum_log_det.total(), sum_nis.total(), n, p)


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


def negative_log_likelihood(model: LinearModel, transition: str,
                            segments: Sequence[Sequence[StepRecord]]) -> float:
    """Return -log L of the trace under the model's Q and R (inf if a step fails)."""
    try:
        with np.errstate(all='ignore'):
            value = -trace_log_likelihood(model, transition, segments)
    except (FilterError, np.linalg.LinAlgError, ArithmeticError):
        return float('inf')
    return value if np.isfinite(value) else float('inf')


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


@dataclass
class FitResult:
    """The maximum-likelihood Q and R, their standard errors and the optimiser's report."""

    Q: FloatArray
    R: FloatArray
    Q_stderr: FloatArray
    R_stderr: FloatArray
    log_likelihood: float
    theta: FloatArray
    theta_stderr: FloatArray
    covariance_log: FloatArray
    names: list[str]
    success: bool
    message: str
    evaluations: int
    at_bound: list[str] = field(default_factory=list)
    hessian_ok: bool = True


class FitError(ValueError):
    """The likelihood could not be maximised (the message says why)."""


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


def _search(f: Objective, start: FloatArray, centre: FloatArray
            ) -> tuple[FloatArray, FloatArray, FloatArray, str, bool]:
    """
    Minimise f from start within centre +- LOG_SEARCH_RADIUS (L-BFGS-B, then Nelder-Mead).

    Return (theta, lower bounds, upper bounds, the optimiser's message, success).
    """
    lo, hi = centre - LOG_SEARCH_RADIUS, centre + LOG_SEARCH_RADIUS
    bounds = list(zip(lo, hi))
    start = np.clip(start, lo, hi)
    res = scipy.optimize.minimize(f, start, method='L-BFGS-B', bounds=bounds,
                                  options={'maxiter': 500, 'ftol': 1e-13, 'gtol': 1e-7})
    theta, message, success = res.x, str(res.message), bool(res.success)
    if not success:
        nm = scipy.optimize.minimize(f, theta, method='Nelder-Mead', bounds=bounds,
                                     options={'xatol': 1e-6, 'fatol': 1e-9, 'maxiter': 2000})
        if nm.fun <= res.fun:
            theta, success = nm.x, bool(nm.success)
            message = f'L-BFGS-B: {res.message}; Nelder-Mead: {nm.message}'
    return np.asarray(theta, dtype=float), lo, hi, message, success


def _product(offsets: FloatArray, k: int) -> list[list[float]]:
    """Return every k-tuple of offsets."""
    grids = np.meshgrid(*([offsets] * k), indexing='ij')
    return np.stack([g.ravel() for g in grids], axis=1).tolist()


def fit(model: LinearModel, transition: str, segments: Sequence[Sequence[StepRecord]], *,
        fit_Q: bool = True, fit_R: bool = True,
        progress: Optional[FitProgress] = None) -> FitResult:
    """
    Maximise the innovation likelihood over log diag(Q) and log diag(R) from the model's.

    Raises FitError when the likelihood is not finite at the start or the optimiser does
    not converge.  The search starts from the best point of a coarse grid around the
    model's values and around the data's own scale (data_scale).  A parameter that runs to
    its search bound (e^{+-25} around that start) is searched again around that bound, up
    to RECENTRES times; one still at its bound then (the likelihood rises without a
    maximum towards 0 or infinity) is listed in `at_bound` and its standard error is NaN.
    progress(evaluations, best log-likelihood) is called after each evaluation.
    """
    r = model.Q.shape[0]
    p = model.C.shape[0]
    if not (fit_Q or fit_R):
        raise FitError('nothing to fit: both Q and R are fixed')
    par = NoiseParameters(r, p, fit_Q, fit_R)
    theta0 = par.start(model.Q, model.R)
    calls = [0]
    best_seen = [float('inf')]

    def nll(theta: FloatArray) -> float:
        calls[0] += 1
        Q, R = par.matrices(theta, model.Q, model.R)
        value = negative_log_likelihood(with_noise(model, Q, R), transition, segments)
        best_seen[0] = min(best_seen[0], value)
        if progress is not None:
            progress(calls[0], -best_seen[0])
        return value

    if not np.isfinite(nll(theta0)):
        raise FitError("the likelihood is not finite at the parameter file's Q and R")
    big = 1e300

    def bounded(theta: FloatArray) -> float:
        value = nll(theta)
        return value if np.isfinite(value) else big

    # the coarse search around the file's values and around the data's own scale: a
    # start far from the data (e^30) can sit on a plateau where no gradient leads back
    theta, value = coarse_start(bounded, theta0)
    scaled, scaled_value = coarse_start(bounded, data_scale(model, segments, par, theta0),
                                        DATA_OFFSETS)
    if scaled_value < value:
        theta = scaled
    centre = np.array(theta, dtype=float)
    for _ in range(RECENTRES + 1):
        theta, lo, hi, message, success = _search(bounded, theta, centre)
        edge = (theta - lo < AT_BOUND) | (hi - theta < AT_BOUND)
        if not (success and np.any(edge)):
            break
        centre = np.where(edge, theta, centre)      # search again around the bound
    best = nll(theta)
    if not success or not np.isfinite(best):
        raise FitError(f'the optimiser did not converge ({message})')
    at_bound = [name for name, e in zip(par.names, edge) if e]
    H = numerical_hessian(nll, theta)
    hessian_ok = bool(np.all(np.isfinite(H)))
    cov = np.full_like(H, np.nan)
    if hessian_ok:
        try:
            np.linalg.cholesky(H)
            cov = np.asarray(np.linalg.inv(H), dtype=float)
        except np.linalg.LinAlgError:
            hessian_ok = False
    se_log = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if hessian_ok else np.full(
        theta.size, np.nan)
    for i, name in enumerate(par.names):
        if name in at_bound:
            se_log[i] = np.nan
    Q, R = par.matrices(theta, model.Q, model.R)
    Qs, Rs = par.stderr_matrices(theta, se_log)
    return FitResult(Q=Q, R=R, Q_stderr=Qs, R_stderr=Rs, log_likelihood=-best, theta=theta,
                     theta_stderr=se_log, covariance_log=cov, names=par.names,
                     success=success, message=message, evaluations=calls[0],
                     at_bound=at_bound, hessian_ok=hessian_ok)
