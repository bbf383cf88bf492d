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
from typing import Iterator, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.noise_search import (AT_BOUND, coarse_start, COARSE_STEPS, DATA_OFFSETS,
                                        data_scale, FitProgress, LOG_L_TOLERANCE,
                                        newton_gap, NoiseParameters, numerical_hessian,
                                        Objective, RECENTRES, search)
from tskf_ros.core.pairwise_sum import PairwiseSum
from tskf_ros.core.step_columns import column_blocks, StepRecord
from tskf_ros.core.timescale_kalman import FilterError, TimeScaleKalmanFilter

LOG_2PI = float(np.log(2.0 * np.pi))
FloatArray = NDArray[np.float64]


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


def _run(kf: TimeScaleKalmanFilter, mus: FloatArray, ys: FloatArray
         ) -> tuple[FloatArray, FloatArray]:
    """Make the steps in one compiled run; return their (e_k, S_k) (those of `step`)."""
    res = kf.run(mus, ys, innovations=True)
    e, S = res.innovation, res.S
    assert e is not None and S is not None     # asked for
    if res.steps == len(mus):
        return e, S
    # the run stopped before a step `step` refuses: made by `step`, which raises saying why
    rest = [kf.step(mu, y) for mu, y in zip(mus[res.steps:], ys[res.steps:])]
    return (np.concatenate([e, [r.innovation for r in rest]]),
            np.concatenate([S, [r.S for r in rest]]))


def _plain_runs(plain: NDArray[np.bool_]) -> Iterator[tuple[int, int, bool]]:
    """Yield (start, end, plain) of the runs of equal values of plain, in order."""
    edges = np.flatnonzero(plain[1:] != plain[:-1]) + 1
    starts = np.concatenate([[0], edges]).tolist()
    ends = np.concatenate([edges, [plain.size]]).tolist()
    for a, b in zip(starts, ends):
        yield a, b, bool(plain[a])


def innovation_blocks(model: LinearModel, transition: str,
                      segments: Sequence[Sequence[StepRecord]], block: int = TRACE_BLOCK
                      ) -> Iterator[tuple[FloatArray, FloatArray]]:
    """
    Run the core filter over the trace; yield (e_k, S_k) of measurement steps in blocks.

    Each segment starts from a fresh filter (x0, P0).  A step with a sample variance
    (use_message_variance) is run with R = variance * mu, so that R / mu is that variance,
    as the estimator session does.  The steps are read a block at a time as columns
    (`step_columns.column_blocks`); each run of measurement steps with the model's R and
    no input is made in one compiled call (`TimeScaleKalmanFilter.run`, the same steps
    as `step`'s) on the columns' slices, the other steps one at a time.  Raises
    FilterError if a step fails.  At most `block` steps are kept at a time: a trace of
    any length runs in bounded memory.
    """
    rows = _Rows(block, model.C.shape[0])
    for segment in segments:
        kf = model.make_filter(transition, allow_nonregressive=True)
        R_model = kf.R
        for cols in column_blocks(segment, block):
            # a measurement with the model's R and no input the model takes
            plain = cols.has_y & ~(cols.variance > 0)
            if model.B is not None:
                plain &= ~cols.has_u
            for a, b, run in _plain_runs(plain):
                if run:
                    assert cols.y is not None       # has_y somewhere
                    yield from rows.add(*_run(kf, cols.mu[a:b], cols.y[a:b]))
                    continue
                for i in range(a, b):
                    rec = cols.record(i)
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
                         segments: Sequence[Sequence[StepRecord]],
                         steps: Optional[int] = None) -> float:
    """
    Return log L of the trace (run_trace(...).log_likelihood()) in bounded memory.

    The NIS and log det S of each block of innovations are added up as np.sum adds the
    whole columns (PairwiseSum): the same number, bit for bit, without keeping them.
    steps: only the first this many measurement steps (all if None or more).
    """
    n = measurement_steps(segments)
    if steps is not None:
        n = min(n, int(steps))
    sum_nis, sum_log_det = PairwiseSum(n), PairwiseSum(n)
    p = model.C.shape[0]
    done = 0
    for e, S in innovation_blocks(model, transition, segments):
        if done == n:
            break
        e, S = e[:n - done], S[:n - done]
        nis, log_det = innovation_terms(e, S)
        sum_nis.add(nis)
        sum_log_det.add(log_det)
        done += len(S)
    return log_likelihood_of(sum_log_det.total(), sum_nis.total(), n, p)


def negative_log_likelihood(model: LinearModel, transition: str,
                            segments: Sequence[Sequence[StepRecord]],
                            steps: Optional[int] = None) -> float:
    """Return -log L of the trace (its first `steps` measurements; inf if a step fails)."""
    try:
        with np.errstate(all='ignore'):
            value = -trace_log_likelihood(model, transition, segments, steps)
    except (FilterError, np.linalg.LinAlgError, ArithmeticError):
        return float('inf')
    return value if np.isfinite(value) else float('inf')


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


def fit(model: LinearModel, transition: str, segments: Sequence[Sequence[StepRecord]], *,
        fit_Q: bool = True, fit_R: bool = True,
        progress: Optional[FitProgress] = None) -> FitResult:
    """
    Maximise the innovation likelihood over log diag(Q) and log diag(R) from the model's.

    Raises FitError when the likelihood is not finite at the start or the optimiser does
    not converge.  The search starts from the best point of a coarse grid around the
    model's values and around the data's own scale (data_scale), its points compared over
    the first COARSE_STEPS measurements.  It stops when an iteration gains less than
    LOG_L_TOLERANCE in log L, if the quadratic model at the Hessian of the standard errors
    then puts the maximum less than LOG_L_TOLERANCE above (newton_gap); else it goes on
    to strict tolerances (noise_search.search).  A parameter that runs to
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
    known: dict[tuple[bytes, Optional[int]], float] = {}
    # the coarse search's steps (None: all of them, the trace is not longer)
    head = COARSE_STEPS if measurement_steps(segments) > COARSE_STEPS else None

    def nll(theta: FloatArray, steps: Optional[int] = None) -> float:
        # a point met again (the Hessian's centre, the search's start) is not re-run
        key = (np.asarray(theta, dtype=float).tobytes(), steps)
        if key in known:
            return known[key]
        calls[0] += 1
        Q, R = par.matrices(theta, model.Q, model.R)
        value = negative_log_likelihood(with_noise(model, Q, R), transition, segments,
                                        steps)
        known[key] = value
        if steps is None:
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

    def coarse(theta: FloatArray) -> float:
        value = nll(theta, head)
        return value if np.isfinite(value) else big

    # the coarse search around the file's values and around the data's own scale: a
    # start far from the data (e^30) can sit on a plateau where no gradient leads back.
    # Its points are e^3 apart: over COARSE_STEPS measurements they differ by far more
    # than the search's tolerance, so they are compared over those only
    theta, value = coarse_start(coarse, theta0)
    scaled, scaled_value = coarse_start(coarse, data_scale(model, segments, par, theta0),
                                        DATA_OFFSETS)
    if scaled_value < value:
        theta = scaled
    search_at = _Search(np.array(theta, dtype=float))
    theta, edge, message, success = search_at.run(bounded, theta)
    H = numerical_hessian(nll, theta) if success else np.full((theta.size,) * 2, np.nan)
    if not (success and newton_gap(nll, theta, H) <= LOG_L_TOLERANCE):
        # a plateau or a bound, where an iteration gains little though the maximum is far
        # (or the Hessian is not positive definite): on to strict tolerances from there
        theta, edge, message, success = search_at.run(bounded, theta, strict=True)
        H = numerical_hessian(nll, theta)
    best = nll(theta)
    if not success or not np.isfinite(best):
        raise FitError(f'the optimiser did not converge ({message})')
    at_bound = [name for name, e in zip(par.names, edge) if e]
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


@dataclass
class _Search:
    """The search's box (its centre) and the recentres left (RECENTRES in all)."""

    centre: FloatArray
    recentres: int = RECENTRES

    def run(self, f: Objective, theta: FloatArray, strict: bool = False
            ) -> tuple[FloatArray, NDArray[np.bool_], str, bool]:
        """
        Return (theta, at its bound, message, success) of `search` from theta.

        A parameter that runs to its search bound is searched again around that bound
        while recentres are left.
        """
        while True:
            theta, lo, hi, message, success = search(f, theta, self.centre, strict)
            edge = (theta - lo < AT_BOUND) | (hi - theta < AT_BOUND)
            if not (success and np.any(edge)) or self.recentres == 0:
                return theta, edge, message, success
            self.recentres -= 1
            self.centre = np.where(edge, theta, self.centre)    # again around the bound
