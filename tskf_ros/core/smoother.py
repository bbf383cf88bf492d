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
(t_{k+1} = t_k + mu_k), in compiled runs (`TimeScaleKalmanFilter.run`, the same bits as its
`step`); it keeps x(t_k|t_k), P(t_k|t_k), the prediction x(t_{k+1}|t_k), P(t_{k+1}|t_k)
and, per distinct mu, the jump F (I + mu A, or e^{A mu}) with each point's index into them.
The backward pass writes x(t_k|T), P(t_k|T) over x(t_k|t_k), P(t_k|t_k) in place: the
forward arrays are the output, and the pass needs only the predictions besides.
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
from tskf_ros.core.matrices import FilterError
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['backward_pass', 'Smoothed', 'rts_smooth', 'smooth_at', 'smoother_gain',
           'smoothed_step', 'warm_up']


class Smoothed(NamedTuple):
    """Smoothed estimates x(t|T) (K, n) and covariances P(t|T) (K, n, n)."""

    xs: NDArray[np.float64]
    Ps: NDArray[np.float64]


class Forward(NamedTuple):
    """What the backward pass needs of the forward pass, one row per point."""

    x_f: NDArray[np.float64]        # x(t_k|t_k)
    P_f: NDArray[np.float64]        # P(t_k|t_k)
    x_p: NDArray[np.float64]        # x(t_{k+1}|t_k)
    P_p: NDArray[np.float64]        # P(t_{k+1}|t_k)
    F: NDArray[np.float64]          # the jumps of the distinct mu
    jump: NDArray[np.intp]          # point k jumps by F[jump[k]]
    inputs: list[Optional[Vector]]  # u(t_k), held over the jump
    kf: TimeScaleKalmanFilter       # the filter that made them (for the partial jumps)


_jit = kernel


@_jit
def smoother_gain(P_f: Matrix, F: Matrix, P_p: Matrix) -> Matrix:
    """Return the RTS gain G = P(t_k|t_k) F^T P(t_{k+1}|t_k)^-1, by a solve (not an inverse)."""
    # G^T = P(t_{k+1}|t_k)^-1 F P(t_k|t_k), as P(t_{k+1}|t_k) and P(t_k|t_k) are symmetric
    FP = np.ascontiguousarray(F) @ np.ascontiguousarray(P_f)
    try:
        Gt = np.linalg.solve(P_p, FP)
    except Exception:       # singular P(t_{k+1}|t_k): the least-squares (pseudo-inverse) gain
        Gt = np.linalg.lstsq(P_p, FP)[0]
    return np.ascontiguousarray(Gt.T)


@_jit
def smoothed_step(x_f: Vector, P_f: Matrix, x_p: Vector, P_p: Matrix, G: Matrix,
                  x_next: Vector, P_next: Matrix) -> tuple[Vector, Matrix]:
    """One backward step: x(t_k|T), P(t_k|T) from the smoothed estimate at t_{k+1}."""
    # x(t_k|T) = x(t_k|t_k) + G_k (x(t_{k+1}|T) - x(t_{k+1}|t_k))      (RTS 1965; Sarkka 8.2)
    x = x_f + G @ (x_next - x_p)
    # P(t_k|T) = P(t_k|t_k) + G_k (P(t_{k+1}|T) - P(t_{k+1}|t_k)) G_k^T  (RTS 1965; Sarkka 8.2)
    P = P_f + G @ (P_next - P_p) @ np.ascontiguousarray(G.T)
    # symmetrised, as halves (as kalman.predict)
    return x, P / 2 + P.T / 2


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
    """Return mu as a 1-D array of finite graininesses > 0, one per point."""
    try:
        m = np.array(mu, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'mu is not numeric: {exc}') from None
    if m.ndim != 1 or m.size == 0:
        raise FilterError(f'mu must be a 1-D sequence of K >= 1 graininesses, got shape {m.shape}')
    bad = np.flatnonzero(~(np.isfinite(m) & (m > 0)))
    if bad.size:
        k = int(bad[0])
        raise FilterError(f'mu[{k}] = {m[k]}: every graininess must be finite and > 0')
    return m


def _rows(values: Optional[ArrayLike], K: int, size: int, name: str, *,
          missing: bool = True) -> list[Optional[Vector]]:
    """
    Split y or u into K rows of `size` entries (None: no value at that point).

    With missing=True (y), an all-NaN row, or a masked row of a numpy masked array, is
    a missing measurement too.
    """
    if values is None:
        return [None] * K
    if isinstance(values, (list, tuple)):
        if len(values) != K:
            raise FilterError(f'{name} must have {K} rows (one per point), got {len(values)}')
        return [None if v is None else _row(v, size, name, k, missing)
                for k, v in enumerate(values)]
    try:
        if isinstance(values, np.ma.MaskedArray):
            values = np.ma.filled(np.ma.asarray(values, dtype=float), np.nan)
        a = np.array(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FilterError(f'{name} is not numeric: {exc}') from None
    if a.ndim == 1 and size == 1:
        a = a.reshape(-1, 1)
    if a.shape != (K, size):
        raise FilterError(f'{name} must have shape {(K, size)} (one row per point), '
                          f'got {a.shape}')
    return [_row(a[k], size, name, k, missing) for k in range(K)]


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


def _forward(A: ArrayLike, C: ArrayLike, mu: ArrayLike, y: Optional[ArrayLike], *,
             Q: ArrayLike, R: ArrayLike, G: Optional[ArrayLike], B: Optional[ArrayLike],
             u: Optional[ArrayLike], D: Optional[ArrayLike], x0: ArrayLike, P0: ArrayLike,
             transition: str) -> Forward:
    """Run the filter at every point (in runs between missing measurements); keep its rows."""
    m = _graininess(mu)
    K = m.size
    kf = TimeScaleKalmanFilter(A, C, Q=Q, R=R, G=G, B=B, D=D, x0=x0, P0=P0,
                               transition=transition)
    n = kf.n
    z = _measured(y, K, kf.p) if u is None else None
    if z is not None:
        # every point measured, no input: one compiled run, no per-point rows
        us: list[Optional[Vector]] = [None] * K
        res = kf.run(m, z)
        if res.steps < K:
            _refused(kf, float(m[res.steps]), z[res.steps], res.steps)
        # the backward pass's F, made once the run's own transitions are freed (with
        # jittered stamps nearly every mu is distinct: a stack as long as the data)
        F, jump = _transitions_of(kf, m)
        return Forward(res.x_corrected, res.P_corrected, res.x_predicted, res.P_predicted,
                       F, jump, us, kf)
    F, jump = _transitions_of(kf, m)
    ys = _rows(y, K, kf.p, 'y')
    us = _rows(u, K, kf.B.shape[1], 'u', missing=False)
    x_f, x_p = np.empty((K, n)), np.empty((K, n))
    P_f, P_p = np.empty((K, n, n)), np.empty((K, n, n))
    for k in range(K):
        mu_k = float(m[k])
        try:
            res1 = kf.step(mu_k, ys[k], us[k])
        except FilterError as exc:
            raise type(exc)(f'point {k} (mu = {mu_k}): {exc}') from None
        x_f[k], P_f[k] = res1.x_corrected, res1.P_corrected
        x_p[k], P_p[k] = res1.x_predicted, res1.P_predicted
    return Forward(x_f, P_f, x_p, P_p, F, jump, us, kf)


def _transitions_of(kf: TimeScaleKalmanFilter, m: NDArray[np.float64]
                    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Return F of each distinct mu of m and the index of each point's in it."""
    values, jump = np.unique(m, return_inverse=True)
    return kf.transition_stack(values).F, jump.astype(np.intp)


def _measured(y: Optional[ArrayLike], K: int, p: int) -> Optional[NDArray[np.float64]]:
    """Return y as a finite (K, p) array, or None where `_rows` must check and split it."""
    if y is None or isinstance(y, (list, tuple, np.ma.MaskedArray)):
        return None
    try:
        z = np.asarray(y, dtype=float)
    except (TypeError, ValueError):
        return None
    if z.ndim == 1 and p == 1:
        z = z.reshape(-1, 1)
    if z.shape != (K, p) or not np.isfinite(z).all():
        return None
    return z


def _refused(kf: TimeScaleKalmanFilter, mu_k: float, y_k: Vector, k: int) -> None:
    """Raise the error `step` gives for point k, where a run stopped."""
    try:
        kf.step(mu_k, y_k)
    except FilterError as exc:
        raise type(exc)(f'point {k} (mu = {mu_k}): {exc}') from None
    raise FilterError(f'point {k} (mu = {mu_k}): the step was refused')


@_jit
def _backward_in_place(x: NDArray[np.float64], P: NDArray[np.float64],
                       x_p: NDArray[np.float64], P_p: NDArray[np.float64],
                       F: NDArray[np.float64], jump: NDArray[np.intp]) -> None:
    """Turn x(t_k|t_k), P(t_k|t_k) into x(t_k|T), P(t_k|T), from the last point back."""
    for k in range(x.shape[0] - 2, -1, -1):
        G = smoother_gain(P[k], F[jump[k]], P_p[k])
        x[k], P[k] = smoothed_step(x[k], P[k], x_p[k], P_p[k], G, x[k + 1], P[k + 1])


def _backward(fw: Forward) -> Smoothed:
    """Run the RTS recursion from the last point's corrected estimate back to t_0."""
    xs, Ps = fw.x_f.copy(), fw.P_f.copy()
    _backward_in_place(xs, Ps, fw.x_p, fw.P_p, np.ascontiguousarray(fw.F), fw.jump)
    return Smoothed(xs, Ps)


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
    # the forward rows become the output: no copy of them
    _backward_in_place(fw.x_f, fw.P_f, fw.x_p, fw.P_p, np.ascontiguousarray(fw.F), fw.jump)
    return Smoothed(fw.x_f, fw.P_f)


def _interpolate(fw: Forward, smooth: Smoothed, k: int, mu_k: float, mu1: float
                 ) -> tuple[Vector, Matrix]:
    """Smoothed estimate at s = t_k + mu1, 0 < mu1 < mu_k, under the model's partial jumps."""
    kf, u = fw.kf, fw.inputs[k]
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
    smooth = _backward(fw)
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
    _backward_in_place(x[None], P[None], x[None], P[None], P[None], np.zeros(1, dtype=np.intp))
