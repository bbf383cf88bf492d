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
The Kalman filter's predict and update: the one implementation of both, compiled with numba.

FilterPy's names and equations (Labbe, FilterPy `KalmanFilter.predict` / `update`;
Simon, Optimal State Estimation, Wiley 2006, eqs. 5.17-5.19):

    predict:   x = F x + B u                  P = F P F^T + Q
    update:    y = z - (H x + d)              S = H P H^T + R
               K = P H^T S^-1                 x = x + K y
               P = (I - K H) P (I - K H)^T + K R K^T                  (Joseph form)

d is an offset of the predicted measurement: Cai et al.'s output offset D for a linear
model, h(x) - H x for an extended filter linearised at x (so H x + d = h(x)).
The time-scale filter, the switching and lifted filters and the scanning EKF all call
these; both are written once over a leading axis of independent runs (`predict_runs`,
`update_runs`: one filter is a stack of one, a batch allocates each intermediate once for
all its runs),
`update_batch` and `predict_batch` run a batch, `update_predict_run` a sequence of steps
of one filter.  The innovation test (a gate,
as robot_localization's rejection threshold) is d^2 = y^T S^-1 y (`mahalanobis2`).
"""

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.jit import kernel

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

# matrix products up to this many multiply-adds run as loops: BLAS's call costs more there
_LOOP_FLOPS = 4096

# compiled with numba on demand (tskf_ros.core.jit), each kernel's source run until then
_jit = kernel


@kernel(interpreted=np.matmul)     # interpreted, the loops cost more than numpy's
def _mm(A: Matrix, B: Matrix) -> Matrix:
    """Return A B: loops for small matrices, BLAS for large ones."""
    n, m = A.shape
    p = B.shape[1]
    if n * m * p > _LOOP_FLOPS:
        return np.ascontiguousarray(A) @ np.ascontiguousarray(B)
    out = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            a = A[i, k]
            for j in range(p):
                out[i, j] += a * B[k, j]
    return out


@kernel(interpreted=np.matmul)
def _mv(A: Matrix, x: Vector) -> Vector:
    """Return A x."""
    n, m = A.shape
    out = np.zeros(n)
    for i in range(n):
        s = 0.0
        for k in range(m):
            s += A[i, k] * x[k]
        out[i] = s
    return out


@_jit
def _inv(S: Matrix) -> Matrix:
    """Return S^-1 by LAPACK (NaN entries when S is singular): `_inv_runs` beyond 2 x 2."""
    p = S.shape[0]
    try:
        return np.linalg.inv(np.ascontiguousarray(S))
    except Exception:       # singular: numba raises LinAlgError's message as an Exception
        return np.full((p, p), np.nan)


# Over runs: a stack of independent filters on a leading axis (a leading axis of 1 is
# shared by every run).  `update` is written once over runs: one filter is a stack of one,
# and a batch allocates each intermediate once for all its runs, not once per run.
Stack = NDArray[np.float64]


def _matmul_vector(A: Stack, x: Stack) -> Stack:
    """Return A[r] x[r] for each run r, by numpy (the interpreted `_mv_runs`)."""
    return np.matmul(A, x[..., None])[..., 0]


@kernel(interpreted=np.matmul)
def _mm_runs(A: Stack, B: Stack) -> Stack:
    """Return A[r] B[r] for each run r: loops for small matrices, BLAS for large ones."""
    runs = max(A.shape[0], B.shape[0])
    n, m, p = A.shape[1], A.shape[2], B.shape[2]
    out = np.empty((runs, n, p))
    for r in range(runs):
        ra = r if A.shape[0] > 1 else 0
        rb = r if B.shape[0] > 1 else 0
        if n * m * p > _LOOP_FLOPS:
            out[r] = np.ascontiguousarray(A[ra]) @ np.ascontiguousarray(B[rb])
        elif n == 2 and m == 2 and p == 2:
            # the loops below, written out (3x faster than loops of unknown bounds): each
            # entry summed from 0 in the order of k, as they do
            a00, a01, a10, a11 = A[ra, 0, 0], A[ra, 0, 1], A[ra, 1, 0], A[ra, 1, 1]
            b00, b01, b10, b11 = B[rb, 0, 0], B[rb, 0, 1], B[rb, 1, 0], B[rb, 1, 1]
            out[r, 0, 0] = (0.0 + a00 * b00) + a01 * b10
            out[r, 0, 1] = (0.0 + a00 * b01) + a01 * b11
            out[r, 1, 0] = (0.0 + a10 * b00) + a11 * b10
            out[r, 1, 1] = (0.0 + a10 * b01) + a11 * b11
        else:
            for i in range(n):
                for j in range(p):
                    s = 0.0
                    for k in range(m):
                        s += A[ra, i, k] * B[rb, k, j]
                    out[r, i, j] = s
    return out


@kernel(interpreted=_matmul_vector)
def _mv_runs(A: Stack, x: Stack) -> Stack:
    """Return A[r] x[r] for each run r."""
    runs = max(A.shape[0], x.shape[0])
    n, m = A.shape[1], A.shape[2]
    out = np.zeros((runs, n))
    for r in range(runs):
        ra = r if A.shape[0] > 1 else 0
        rx = r if x.shape[0] > 1 else 0
        for i in range(n):
            s = 0.0
            for k in range(m):
                s += A[ra, i, k] * x[rx, k]
            out[r, i] = s
    return out


@_jit
def _inv_runs(S: Stack) -> Stack:
    """
    Return S[r]^-1 for each run r.

    Closed forms for 1 x 1 and 2 x 2 (inf or NaN entries when S[r] is singular), LAPACK
    beyond (`_inv`).
    """
    p = S.shape[1]
    out = np.empty(S.shape)
    for r in range(S.shape[0]):
        if p == 1:
            out[r, 0, 0] = 1.0 / S[r, 0, 0]
        elif p == 2:
            a, b, c, d = S[r, 0, 0], S[r, 0, 1], S[r, 1, 0], S[r, 1, 1]
            det = a * d - b * c
            out[r, 0, 0], out[r, 0, 1] = d / det, -b / det
            out[r, 1, 0], out[r, 1, 1] = -c / det, a / det
        else:
            out[r] = _inv(S[r])
    return out


@_jit
def _t(A: Stack) -> Stack:
    """Return A[r]^T for each run r."""
    return A.transpose((0, 2, 1))


@_jit
def _symmetric_runs(P: Stack) -> Stack:
    """
    Return (P[r] + P[r]^T) / 2 for each run r, as halves (entries near 1e308 stay finite).

    In place: P is an intermediate of its caller.
    """
    n = P.shape[1]
    for r in range(P.shape[0]):
        for i in range(n):
            for j in range(i, n):
                P[r, i, j] = P[r, j, i] = P[r, i, j] / 2 + P[r, j, i] / 2
    return P


@_jit
def predict_runs(x: Stack, P: Stack, F: Stack, Q: Stack, Bu: Stack) -> tuple[Stack, Stack]:
    """Time update of each run; Bu is B u (zeros without an input)."""
    # x = F x + B u (each sum in place on the product, a new array: the same sums)
    x = _mv_runs(F, x)
    x += Bu
    # P = F P F^T + Q
    P = _mm_runs(_mm_runs(F, P), _t(F))
    P += Q
    return x, _symmetric_runs(P)


@_jit
def predict(x: Vector, P: Matrix, F: Matrix, Q: Matrix, Bu: Vector) -> tuple[Vector, Matrix]:
    """Time update of one run (a stack of one for predict_runs); Bu is B u."""
    x_, P_ = predict_runs(x[None], P[None], F[None], Q[None], Bu[None])
    return x_[0], P_[0]


@_jit
def innovation_runs(x: Stack, P: Stack, z: Stack, H: Stack, R: Stack, d: Stack
                    ) -> tuple[Stack, Stack, Stack]:
    """Return the innovation y, its covariance S and P H^T of each run."""
    # y = z - (H x + d)
    Hx_d = _mv_runs(H, x)
    Hx_d += d
    y = z - Hx_d
    # S = H P H^T + R
    PHt = _mm_runs(P, _t(H))
    S = _mm_runs(H, PHt)
    S += R
    return y, S, PHt


@_jit
def innovation(x: Vector, P: Matrix, z: Vector, H: Matrix, R: Matrix, d: Vector
               ) -> tuple[Vector, Matrix, Matrix]:
    """Return the innovation y, its covariance S and P H^T (`innovation_runs`, one run)."""
    y, S, PHt = innovation_runs(x[None], P[None], z[None], H[None], R[None], d[None])
    return y[0], S[0], PHt[0]


@_jit
def mahalanobis2(x: Vector, P: Matrix, z: Vector, H: Matrix, R: Matrix, d: Vector
                 ) -> tuple[float, Vector]:
    """
    Return (y^T S^-1 y, y): the squared Mahalanobis distance of z from the prediction.

    -1 when S is singular (no distance); inf or NaN when an entry overflows.
    """
    y, S, _ = innovation(x, P, z, H, R, d)
    p = S.shape[0]
    if p == 1:
        if S[0, 0] == 0.0:
            return -1.0, y
        return y[0] * y[0] / S[0, 0], y
    det = np.linalg.det(np.ascontiguousarray(S))
    if det == 0.0:
        return -1.0, y
    return float(y @ np.linalg.solve(np.ascontiguousarray(S), y)), y


@_jit
def update_runs(x: Stack, P: Stack, z: Stack, H: Stack, R: Stack, d: Stack
                ) -> tuple[Stack, Stack, Stack, Stack, Stack]:
    """Measurement update of each run; returns (x, P, y, S, K)."""
    y, S, PHt = innovation_runs(x, P, z, H, R, d)
    # K = P H^T S^-1
    K = _mm_runs(PHt, _inv_runs(S))
    # x = x + K y
    Ky = _mv_runs(K, y)
    Ky += x
    x = Ky
    # P = (I - K H) P (I - K H)^T + K R K^T: the Joseph form (Bucy & Joseph 1968; Simon
    # eq. 5.19), right for any K, so that an error in K changes P only to second order.  It
    # is evaluated as written, as congruences of P and R, which keeps P positive
    # semi-definite when P is ill-conditioned; expanding it with S = H P H^T + R into
    # P - K (H P) - (P H^T) K^T + K S K^T keeps the algebra but not that property
    # (test/core/test_kalman.py measures both)
    I_KH = np.eye(P.shape[1]) - _mm_runs(K, H)
    P = _mm_runs(_mm_runs(I_KH, P), _t(I_KH))
    P += _mm_runs(_mm_runs(K, R), _t(K))
    return x, _symmetric_runs(P), y, S, K


@_jit
def update(x: Vector, P: Matrix, z: Vector, H: Matrix, R: Matrix, d: Vector
           ) -> tuple[Vector, Matrix, Vector, Matrix, Matrix]:
    """Measurement update of one run (a stack of one for update_runs): (x, P, y, S, K)."""
    x_, P_, y, S, K = update_runs(x[None], P[None], z[None], H[None], R[None], d[None])
    return x_[0], P_[0], y[0], S[0], K[0]


@_jit
def finite(x: Vector, P: Matrix) -> bool:
    """Tell whether every entry of x and P is finite."""
    # a sum is finite when every entry is; only a sum that is not needs the full check
    if np.isfinite(x.sum()) and np.isfinite(P.sum()):
        return True
    return bool(np.all(np.isfinite(x)) and np.all(np.isfinite(P)))


OK, NOT_POSITIVE, NOT_FINITE = 0, 1, 2     # what update_predict reports


@_jit
def update_predict(x: Vector, P: Matrix, z: Vector, H: Matrix, R: Matrix, d: Vector,
                   F: Matrix, Q: Matrix, Bu: Vector
                   ) -> tuple[Vector, Matrix, Vector, Matrix, Vector, Matrix, int]:
    """
    Run update then predict in one call: (x(t|t), P(t|t), x(sigma), P(sigma), y, S, status).

    status is OK, NOT_POSITIVE (a diagonal entry of S is not > 0: P or R is not positive
    semi-definite) or NOT_FINITE (an estimate has an entry that is not finite).
    """
    x_c, P_c, y, S, _ = update(x, P, z, H, R, d)
    x_p, P_p = predict(x_c, P_c, F, Q, Bu)
    status = OK
    for i in range(S.shape[0]):
        if not S[i, i] > 0:
            status = NOT_POSITIVE
    if status == OK and not (finite(x_c, P_c) and finite(x_p, P_p)):
        status = NOT_FINITE
    return x_c, P_c, x_p, P_p, y, S, status


# The node's per-input calls write their arrays into arrays the caller allocates and return
# a scalar: numba.pycc's functions (tskf_ros.core.aot) box each array they return with an
# unpickling of numpy's array class, about 0.5 us an array, where an array passed in costs
# its argument check only.  Both compose the kernels above (no equation written again).


@_jit
def update_predict_into(x: Vector, P: Matrix, z: Vector, H: Matrix, R: Matrix, d: Vector,
                        F: Matrix, Q: Matrix, Bu: Vector, x_c: Vector, P_c: Matrix,
                        x_p: Vector, P_p: Matrix, y: Vector, S: Matrix) -> int:
    """
    Run `update_predict`, writing x(t|t), P(t|t), x(sigma), P(sigma), y, S into the last six.

    Return its status.  An array of the wrong shape (n = len(x), p = len(z)) raises
    ValueError, nothing written.
    """
    n, p = x.shape[0], z.shape[0]
    if not (x_c.shape == x_p.shape == (n,) and P_c.shape == P_p.shape == (n, n)
            and y.shape == (p,) and S.shape == (p, p)):
        raise ValueError('update_predict_into: the arrays written must be of shapes '
                         '(n,), (n, n), (n,), (n, n), (p,), (p, p)')
    xc, Pc, xp, Pp, y_, S_, status = update_predict(x, P, z, H, R, d, F, Q, Bu)
    x_c[:], P_c[:], x_p[:], P_p[:], y[:], S[:] = xc, Pc, xp, Pp, y_, S_
    return status


@_jit
def mahalanobis2_into(x: Vector, P: Matrix, z: Vector, H: Matrix, R: Matrix, d: Vector,
                      y: Vector) -> float:
    """
    Return `mahalanobis2`'s y^T S^-1 y, writing its innovation into y.

    A y of the wrong shape (len(z)) raises ValueError, nothing written.
    """
    if y.shape[0] != z.shape[0]:
        raise ValueError('mahalanobis2_into: y must be of shape (p,), p = len(z)')
    d2, y_ = mahalanobis2(x, P, z, H, R, d)
    y[:] = y_
    return d2


STOPPED = 3     # what update_predict_run reports when the innovation test stops it


@_jit
def update_predict_run(x: Vector, P: Matrix, z: NDArray[np.float64], H: Matrix,
                       R: NDArray[np.float64], d: Vector, F: NDArray[np.float64],
                       Q: NDArray[np.float64], Bu: NDArray[np.float64], jump: NDArray[np.intp],
                       z_test: NDArray[np.float64], R_test: Matrix, limit2: float
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                  NDArray[np.float64], NDArray[np.float64], int, int]:
    """
    Run `update_predict` for k = 0, 1, ... from the previous step's prediction (from x, P).

    Step k: z[k], R[k], F[jump[k]], Q[jump[k]], Bu[jump[k]].  It stops before keeping
    a step whose status is not OK, or (limit2 >= 0) whose prediction puts z_test[k] beyond
    mahalanobis2 <= limit2 with R_test (the status is then STOPPED; NaN stops too).
    Returns the rows (x(t|t), P(t|t), x(sigma), P(sigma)) of the steps kept, their number
    and the status of the step that stopped the run (OK if none did).
    """
    K, n = z.shape[0], x.shape[0]
    x_c, P_c = np.empty((K, n)), np.empty((K, n, n))
    x_p, P_p = np.empty((K, n)), np.empty((K, n, n))
    for k in range(K):
        i = jump[k]
        xc, Pc, xp, Pp, _, _, status = update_predict(x, P, z[k], H, R[k], d, F[i], Q[i],
                                                      Bu[i])
        if status != OK:
            return x_c[:k], P_c[:k], x_p[:k], P_p[:k], k, status
        if limit2 >= 0.0:
            d2, _ = mahalanobis2(xp, Pp, z_test[k], H, R_test, d)
            if not d2 <= limit2:
                return x_c[:k], P_c[:k], x_p[:k], P_p[:k], k, STOPPED
        x_c[k], P_c[k], x_p[k], P_p[k] = xc, Pc, xp, Pp
        x, P = xp, Pp
    return x_c, P_c, x_p, P_p, K, OK


@_jit
def update_batch(x: NDArray[np.float64], P: NDArray[np.float64], z: NDArray[np.float64],
                 H: NDArray[np.float64], R: NDArray[np.float64], d: NDArray[np.float64]
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Run `update` for every run i on (x[i], P[i], z[i], H[i], R[i], d[i]); returns (x, P)."""
    x_out, P_out, _, _, _ = update_runs(x, P, z, H, R, d)
    return x_out, P_out


@_jit
def predict_batch(x: NDArray[np.float64], P: NDArray[np.float64], F: Matrix, Q: Matrix,
                  Bu: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Run `predict` for every run i on (x[i], P[i], Bu[i]), F and Q shared; returns (x, P)."""
    return predict_runs(x, P, F[None], Q[None], Bu)


def warm_up() -> None:
    """Compile every kernel for float64 arrays, or load them from numba's on-disk cache."""
    x, P, F, z = np.zeros(2), np.eye(2), np.eye(2), np.zeros(1)
    H, R = np.ones((1, 2)), np.eye(1)
    update_predict(x, P, z, H, R, z, F, P, x)
    update_predict_into(x, P, z, H, R, z, F, P, x, x.copy(), P.copy(), x.copy(), P.copy(),
                        z.copy(), R.copy())
    mahalanobis2_into(x, P, z, H, R, z, z.copy())
    predict(x, P, F, P, x)
    update(x, P, z, H, R, z)
    mahalanobis2(x, P, z, H, R, z)
    z2 = np.zeros((1, 1))
    update_predict_run(x, P, z2, H, R[None], z, F[None], P[None], x[None],
                       np.zeros(1, dtype=np.intp), z2, R, 1.0)
    update_batch(x[None], P[None], x[None], F[None], P[None], x[None])
    predict_batch(x[None], P[None], F, P, x[None])
