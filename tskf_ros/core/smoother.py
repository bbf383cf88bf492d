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
Rauch-Tung-Striebel smoother for the time-scale Kalman filter (Bohner & Wintz 2013, Table 3).

Forward: the filter at the points t_0 < ... < t_{K-1} of the time scale
(t_{k+1} = t_k + mu_k), in compiled runs between missing measurements
(`TimeScaleKalmanFilter.run`, the same bits as its `step`), chunk by chunk; it keeps only
x(t_k|t_k), P(t_k|t_k), which become the output: the backward pass writes x(t_k|T),
P(t_k|T) over them in place, from the last point back, remaking each point's prediction
x(t_{k+1}|t_k), P(t_{k+1}|t_k) and jump F (I + mu A, or e^{A mu}) from x(t_k|t_k),
P(t_k|t_k) and mu_k with the filter's own transitions and `kalman.predict`, chunk by
chunk.  Peak memory is the output and one chunk, whatever K.
Backward (Rauch, Tung & Striebel, AIAA J. 3, 1965; Sarkka, Bayesian Filtering and
Smoothing, 2013, Theorem 8.2), from x(t_{K-1}|T) = x(t_{K-1}|t_{K-1}):

    G_k      = P(t_k|t_k) F_k^T P(t_{k+1}|t_k)^-1
    x(t_k|T) = x(t_k|t_k) + G_k (x(t_{k+1}|T) - x(t_{k+1}|t_k))
    P(t_k|T) = P(t_k|t_k) + G_k (P(t_{k+1}|T) - P(t_{k+1}|t_k)) G_k^T

G_k is solved for (G_k^T = P(t_{k+1}|t_k)^-1 F_k P(t_k|t_k)), not inverted; the backward
step is compiled with numba and shared with the fixed-lag smoother.  Between points
(`smooth_at`), s = t_k + mu' is a point with no measurement on the jumps mu' and
mu_k - mu': the filter's predict to s and on to t_{k+1}, then the same step from s.
Derivation and conventions: doc/design/smoother.md.
"""

import math
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core import kalman
from tskf_ros.core.jit import kernel
from tskf_ros.core.kalman import _mm_runs, _mv_runs, _symmetric_runs, _t, predict
from tskf_ros.core.matrices import FilterError
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['backward_pass', 'Smoothed', 'rts_smooth', 'smooth_at', 'smoother_gain',
           'smoother_gain_runs', 'smoothed_step', 'smoothed_step_runs', 'warm_up']


class Smoothed(NamedTuple):
    """Smoothed estimates x(t|T) (K, n) and covariances P(t|T) (K, n, n)."""

    xs: NDArray[np.float64]
    Ps: NDArray[np.float64]


class Forward(NamedTuple):
    """The forward pass: x(t_k|t_k), P(t_k|t_k) per point and what remakes its jumps."""

    x_f: NDArray[np.float64]            # x(t_k|t_k) (K, n)
    P_f: NDArray[np.float64]            # P(t_k|t_k) (K, n, n)
    mu: NDArray[np.float64]             # the graininess of each point (K,)
    inputs: Optional[NDArray[np.float64]]   # u(t_k) (K, m), a row of NaN: none; or None
    kf: TimeScaleKalmanFilter           # the filter that made them (its transitions)


# the points of one compiled run or one backward chunk: about 1 MiB of output rows, so
# that the run's own arrays (its predictions, the jumps of its distinct mu) stay small
_CHUNK_BYTES = 1 << 20


_jit = kernel


@_jit
def smoother_gain(P_f: Matrix, F: Matrix, P_p: Matrix) -> Matrix:
    """Return the RTS gain G = P(t_k|t_k) F^T P(t_{k+1}|t_k)^-1, by a solve (not an inverse)."""
    # G^T = P(t_{k+1}|t_k)^-1 F P(t_k|t_k), as P(t_{k+1}|t_k) and P(t_k|t_k) are symmetric
    FP = np.ascontiguousarray(F) @ np.ascontiguousarray(P_f)
    solved = True
    try:
        Gt = np.linalg.solve(P_p, FP)
    except Exception:
        solved = False      # (nothing raised in here: compiled, a raise there is not caught)
        Gt = np.full(FP.shape, np.nan)      # a run that is not finite: nor is its gain
    if not solved and np.all(np.isfinite(P_p)) and np.all(np.isfinite(FP)):
        # singular P(t_{k+1}|t_k): the least-squares (pseudo-inverse) gain
        Gt = np.linalg.lstsq(P_p, FP)[0]
    return np.ascontiguousarray(Gt.T)


@_jit
def smoother_gain_runs(P_f: NDArray[np.float64], F: NDArray[np.float64],
                       P_p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Return each run's RTS gain (`smoother_gain`): P_f, P_p (runs, n, n), F (n, n)."""
    G = np.empty_like(P_f)
    for r in range(P_f.shape[0]):
        G[r] = smoother_gain(P_f[r], F, P_p[r])
    return G


@_jit
def smoothed_step_runs(x_f: NDArray[np.float64], P_f: NDArray[np.float64],
                       x_p: NDArray[np.float64], P_p: NDArray[np.float64],
                       G: NDArray[np.float64], x_next: NDArray[np.float64],
                       P_next: NDArray[np.float64]
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One backward step of each run: x(t_k|T), P(t_k|T) from the smoothed ones at t_{k+1}."""
    # x(t_k|T) = x(t_k|t_k) + G_k (x(t_{k+1}|T) - x(t_{k+1}|t_k))      (RTS 1965; Sarkka 8.2)
    x = x_f + _mv_runs(G, x_next - x_p)
    # P(t_k|T) = P(t_k|t_k) + G_k (P(t_{k+1}|T) - P(t_{k+1}|t_k)) G_k^T  (RTS 1965; Sarkka 8.2)
    P = P_f + _mm_runs(_mm_runs(G, P_next - P_p), _t(G))
    # symmetrised, as halves (as kalman.predict)
    return x, _symmetric_runs(P)


@_jit
def smoothed_step(x_f: Vector, P_f: Matrix, x_p: Vector, P_p: Matrix, G: Matrix,
                  x_next: Vector, P_next: Matrix) -> tuple[Vector, Matrix]:
    """One backward step of one run (a stack of one for `smoothed_step_runs`)."""
    x, P = smoothed_step_runs(x_f[None], P_f[None], x_p[None], P_p[None], G[None],
                              x_next[None], P_next[None])
    return x[0], P[0]


@_jit
def backward_pass(x_f: NDArray[np.float64], P_f: NDArray[np.float64],
                  x_p: NDArray[np.float64], P_p: NDArray[np.float64],
                  G: NDArray[np.float64], start: int, count: int,
                  xs: NDArray[np.float64], Ps: NDArray[np.float64]) -> None:
    """
    Smooth `count` points kept in ring arrays from row `start` on, oldest first.

    Row j of x_f, P_f, x_p, P_p, G holds point j's x(t|t), P(t|t), its prediction at
    the next point and its gain; rows wrap around (a window).  Writes x(t|T), P(t|T)
    into xs[:count], Ps[:count], oldest first; T is the newest point.
    """
    cap = x_f.shape[0]
    last = (start + count - 1) % cap
    # the newest point: nothing after it, x(T|T) is its corrected estimate
    xs[count - 1] = x_f[last]
    Ps[count - 1] = P_f[last]
    for i in range(count - 2, -1, -1):
        j = (start + i) % cap
        x, P = smoothed_step(x_f[j], P_f[j], x_p[j], P_p[j], G[j], xs[i + 1], Ps[i + 1])
        xs[i] = x
        Ps[i] = P


def _graininess(mu: ArrayLike) -> Vector:
    """Return mu as a 1-D array of finite graininesses > 0, one per point (not copied)."""
    try:
        m = np.asarray(mu, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'mu is not numeric: {exc}') from None
    if m.ndim != 1 or m.size == 0:
        raise FilterError(f'mu must be a 1-D sequence of K >= 1 graininesses, got shape {m.shape}')
    bad = np.flatnonzero(~(np.isfinite(m) & (m > 0)))
    if bad.size:
        k = int(bad[0])
        raise FilterError(f'mu[{k}] = {m[k]}: every graininess must be finite and > 0')
    return m


def _table(values: Optional[ArrayLike], K: int, size: int, name: str, *,
           missing: bool = True) -> Optional[NDArray[np.float64]]:
    """
    Return y or u as a checked (K, size) array, a row of NaN where a point has no value.

    A row None, or (with missing=True, for y) an all-NaN row or a masked row of a numpy
    masked array, is no value at that point.  A float array of that shape is not copied.
    """
    if values is None:
        return None
    if isinstance(values, (list, tuple)):
        if len(values) != K:
            raise FilterError(f'{name} must have {K} rows (one per point), got {len(values)}')
        table = np.full((K, size), np.nan)
        for k, v in enumerate(values):
            row = None if v is None else _row(v, size, name, k, missing)
            if row is not None:
                table[k] = row
        return table
    try:
        if isinstance(values, np.ma.MaskedArray):
            values = np.ma.filled(np.ma.asarray(values, dtype=float), np.nan)
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'{name} is not numeric: {exc}') from None
    if a.ndim == 1 and size == 1:
        a = a.reshape(-1, 1)
    if a.shape != (K, size):
        raise FilterError(f'{name} must have shape {(K, size)} (one row per point), '
                          f'got {a.shape}')
    ok = np.isfinite(a).all(axis=1)
    if missing:
        ok |= np.isnan(a).all(axis=1)
    bad = np.flatnonzero(~ok)
    if bad.size:
        _row(a[bad[0]], size, name, int(bad[0]), missing)     # raises, saying why
    return a


def _row(value: ArrayLike, size: int, name: str, k: int, missing: bool) -> Optional[Vector]:
    """Return one row of y or u, None when it is all NaN and missing values are allowed."""
    try:
        v = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'{name}[{k}] is not numeric: {exc}') from None
    if v.shape != (size,):
        raise FilterError(f'{name}[{k}] must have {size} entries, got {v.size}')
    if np.isfinite(v).all():
        return v
    if missing and np.isnan(v).all():
        return None
    if missing:
        raise FilterError(f'{name}[{k}] = {v}: a row is either all NaN (missing) or finite')
    raise FilterError(f'{name}[{k}] = {v} has non-finite entries')


def _at(table: Optional[NDArray[np.float64]], k: int) -> Optional[Vector]:
    """Return row k of a `_table`, None where the point has no value."""
    if table is None or np.isnan(table[k, 0]):
        return None
    return table[k]


def _chunk(n: int) -> int:
    """Return the points of one chunk for a state of n: _CHUNK_BYTES of x(t|t), P(t|t)."""
    return max(16, _CHUNK_BYTES // (8 * n * (n + 1)))


def _forward(A: ArrayLike, C: ArrayLike, mu: ArrayLike, y: Optional[ArrayLike], *,
             Q: ArrayLike, R: ArrayLike, G: Optional[ArrayLike], B: Optional[ArrayLike],
             u: Optional[ArrayLike], D: Optional[ArrayLike], x0: ArrayLike, P0: ArrayLike,
             transition: str) -> Forward:
    """Run the filter at every point, keeping only x(t_k|t_k), P(t_k|t_k)."""
    m = _graininess(mu)
    K = m.size
    kf = TimeScaleKalmanFilter(A, C, Q=Q, R=R, G=G, B=B, D=D, x0=x0, P0=P0,
                               transition=transition)
    z = _table(y, K, kf.p, 'y')
    us = _table(u, K, kf.B.shape[1], 'u', missing=False)
    fw = Forward(np.empty((K, kf.n)), np.empty((K, kf.n, kf.n)), m, us, kf)
    if us is not None:
        # an input per point: the filter's step at each (its B_d u is made per step)
        for k in range(K):
            _step(fw, k, _at(z, k))
        return fw
    # the stretches measured at every point in compiled runs, in chunks (the run keeps
    # its predictions and the jumps of its distinct mu: with jittered stamps nearly every
    # mu is distinct, so as long as the run); a missing measurement is one step
    chunk = _chunk(kf.n)
    for a in range(0, K, chunk):
        b = min(a + chunk, K)
        measured = np.zeros(b - a, dtype=bool) if z is None else ~np.isnan(z[a:b, 0])
        edges = np.flatnonzero(measured[1:] != measured[:-1]) + 1 + a
        for s, e in zip(np.concatenate(([a], edges)), np.concatenate((edges, [b]))):
            if z is not None and measured[s - a]:
                _run(fw, z, int(s), int(e))
            else:
                for k in range(s, e):
                    _step(fw, k, None)
    return fw


def _run(fw: Forward, z: NDArray[np.float64], a: int, b: int) -> None:
    """Filter points a to b - 1, all measured, no input, in one compiled run."""
    res = fw.kf.run(fw.mu[a:b], z[a:b])
    fw.x_f[a:a + res.steps] = res.x_corrected
    fw.P_f[a:a + res.steps] = res.P_corrected
    if res.steps < b - a:
        # the run stopped before a step that `step` refuses: its error, with the point
        _step(fw, a + res.steps, z[a + res.steps])
        raise FilterError(f'point {a + res.steps} (mu = {fw.mu[a + res.steps]}): '
                          'the step was refused')


def _step(fw: Forward, k: int, y_k: Optional[Vector]) -> None:
    """Filter point k with the filter's step; an error names the point."""
    mu_k = float(fw.mu[k])
    try:
        res = fw.kf.step(mu_k, y_k, _at(fw.inputs, k))
    except FilterError as exc:
        raise type(exc)(f'point {k} (mu = {mu_k}): {exc}') from None
    fw.x_f[k], fw.P_f[k] = res.x_corrected, res.P_corrected


@_jit
def _backward_in_place(x: NDArray[np.float64], P: NDArray[np.float64],
                       F: NDArray[np.float64], Q: NDArray[np.float64],
                       Bu: NDArray[np.float64], jump: NDArray[np.intp],
                       start: int, stop: int) -> None:
    """
    Turn x(t_k|t_k), P(t_k|t_k) into x(t_k|T), P(t_k|T) for k = stop - 1 down to start.

    x[stop], P[stop] are smoothed already; point k jumps by F[i], Q[i], i = jump[k - start],
    with the input Bu[k - start].
    """
    for k in range(stop - 1, start - 1, -1):
        i = jump[k - start]
        # x(t_{k+1}|t_k), P(t_{k+1}|t_k): the filter's own prediction (kalman.predict on
        # the same x(t_k|t_k), P(t_k|t_k) and jump, the same bits), made again here rather
        # than kept from the forward pass
        x_p, P_p = predict(x[k], P[k], F[i], Q[i], Bu[k - start])
        G = smoother_gain(P[k], F[i], P_p)
        x[k], P[k] = smoothed_step(x[k], P[k], x_p, P_p, G, x[k + 1], P[k + 1])


def _backward(fw: Forward, x: NDArray[np.float64], P: NDArray[np.float64]) -> None:
    """
    Run the RTS recursion over x = x(t_k|t_k), P = P(t_k|t_k), in place, to t_0.

    In chunks from the last point back, each with the jumps of its distinct mu (made in
    one call, as the run made them), so that no array is as long as the data but x, P.
    """
    kf, m, K = fw.kf, fw.mu, fw.mu.size
    chunk = _chunk(kf.n)
    uses_B = fw.inputs is not None and bool(np.any(kf.B))
    for b in range(K - 1, 0, -chunk):
        a = max(b - chunk, 0)
        values, jump = np.unique(m[a:b], return_inverse=True)
        jumps = kf.transition_stack(values)
        Bu = np.zeros((b - a, kf.n))
        if uses_B:
            for k in range(a, b):
                u_k = _at(fw.inputs, k)
                if u_k is not None:     # as `step` makes it: B_d u
                    Bu[k - a] = jumps.Bd[jump[k - a]] @ u_k
        _backward_in_place(x, P, np.ascontiguousarray(jumps.F), np.ascontiguousarray(jumps.Qd),
                           Bu, jump.reshape(-1).astype(np.intp), a, b)


def rts_smooth(A: ArrayLike, C: ArrayLike, mu: ArrayLike, y: Optional[ArrayLike], *,
               Q: ArrayLike, R: ArrayLike, G: Optional[ArrayLike] = None,
               B: Optional[ArrayLike] = None, u: Optional[ArrayLike] = None,
               D: Optional[ArrayLike] = None, x0: ArrayLike, P0: ArrayLike,
               transition: str = 'euler') -> Smoothed:
    """
    Return x(t_k|T), P(t_k|T) at the K points t_0 < ... < t_{K-1} of a time scale.

    The model and keywords are TimeScaleKalmanFilter's; x0, P0 are the prior at t_0.
    mu has K entries: mu[k] = t_{k+1} - t_k is the graininess of point k, which also
    weighs its measurement (R_d = R / mu[k]); the jump of mu[K-1] is not used, its
    measure is.  y has K rows of p entries (a row of NaN or None: no measurement),
    u None or K rows (u[k] acts over the jump from t_k; u[K-1] is not used).
    """
    fw = _forward(A, C, mu, y, Q=Q, R=R, G=G, B=B, u=u, D=D, x0=x0, P0=P0,
                  transition=transition)
    # the forward rows become the output, smoothed in place: no copy of them
    _backward(fw, fw.x_f, fw.P_f)
    return Smoothed(fw.x_f, fw.P_f)


def _interpolate(fw: Forward, smooth: Smoothed, k: int, mu_k: float, mu1: float
                 ) -> tuple[Vector, Matrix]:
    """Smoothed estimate at s = t_k + mu1, 0 < mu1 < mu_k, under the model's partial jumps."""
    kf, u = fw.kf, _at(fw.inputs, k)
    F1, Q1, B1 = kf.transition_matrices(mu1)
    F2, Q2, B2 = kf.transition_matrices(mu_k - mu1)
    # C order, the layout the kernels are compiled for (e^{A mu} may come transposed)
    F1, F2 = np.ascontiguousarray(F1), np.ascontiguousarray(F2)
    zero = np.zeros(kf.n)
    Bu1 = zero if u is None else B1 @ u
    Bu2 = zero if u is None else B2 @ u
    # x(s|t_k), P(s|t_k): the filter's predict over mu' (no measurement at s)
    x_s, P_s = kalman.predict(fw.x_f[k], fw.P_f[k], F1, Q1, Bu1)
    # x(t_{k+1}|t_k) through s: predict over mu_k - mu'
    x_p, P_p = kalman.predict(x_s, P_s, F2, Q2, Bu2)
    G = smoother_gain(P_s, F2, P_p)
    return smoothed_step(x_s, P_s, x_p, P_p, G, smooth.xs[k + 1], smooth.Ps[k + 1])


def smooth_at(times: ArrayLike, A: ArrayLike, C: ArrayLike, mu: ArrayLike,
              y: Optional[ArrayLike], *, t0: float = 0.0, Q: ArrayLike, R: ArrayLike,
              G: Optional[ArrayLike] = None, B: Optional[ArrayLike] = None,
              u: Optional[ArrayLike] = None, D: Optional[ArrayLike] = None,
              x0: ArrayLike, P0: ArrayLike, transition: str = 'euler') -> Smoothed:
    """
    Return the smoothed estimate and covariance at any times in [t_0, t_{K-1}].

    The points are t_0 = t0 and t_{k+1} = t_k + mu[k]; the other arguments are
    `rts_smooth`'s.  At a point the result is the point's; at s in (t_k, t_{k+1}) it is
    the backward step from t_{k+1} to s with the jumps s - t_k and t_{k+1} - s of the
    same transition (s treated as a point without a measurement).
    """
    try:
        ts = np.array(times, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'times is not numeric: {exc}') from None
    m = _graininess(mu)
    try:
        start = float(t0)
    except (TypeError, ValueError):
        raise FilterError(f't0 must be a number, got {t0!r}') from None
    if not math.isfinite(start):
        raise FilterError(f't0 must be finite, got {start}')
    points = start + np.concatenate(([0.0], np.cumsum(m[:-1])))
    outside = ~((ts >= points[0]) & (ts <= points[-1]))
    if outside.any():
        s = ts[np.flatnonzero(outside)[0]]
        raise FilterError(f'time {s} is outside the points [{points[0]}, {points[-1]}]')
    fw = _forward(A, C, m, y, Q=Q, R=R, G=G, B=B, u=u, D=D, x0=x0, P0=P0,
                  transition=transition)
    smooth = Smoothed(fw.x_f.copy(), fw.P_f.copy())
    _backward(fw, smooth.xs, smooth.Ps)
    n = fw.kf.n
    xs, Ps = np.empty((ts.size, n)), np.empty((ts.size, n, n))
    for i, s in enumerate(ts):
        # the point at or before s
        k = int(np.searchsorted(points, s, side='right')) - 1
        mu1 = float(s - points[k])
        if mu1 >= m[k]:         # s rounds onto t_{k+1}
            k, mu1 = k + 1, 0.0
        if mu1 == 0.0:
            xs[i], Ps[i] = smooth.xs[k], smooth.Ps[k]
        else:
            xs[i], Ps[i] = _interpolate(fw, smooth, k, float(m[k]), mu1)
    return Smoothed(xs, Ps)


def warm_up() -> None:
    """Compile the backward kernels for float64 arrays, or load them from numba's cache."""
    x, P = np.zeros(2), np.eye(2)
    G = smoother_gain(P, P, P)
    smoothed_step(x, P, x, P, G, x, P)
    backward_pass(x[None], P[None], x[None], P[None], G[None], 0, 1, x[None], P[None])
    _backward_in_place(x[None], P[None], P[None], P[None], x[None], np.zeros(1, dtype=np.intp),
                       0, 0)
