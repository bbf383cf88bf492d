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

"""Checked conversion of model matrices and vectors, and the covariance tests the filters use."""

import math
from typing import Any, Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

FLOAT64 = np.dtype(float)


class FilterError(ValueError):
    """Bad model, bad step, or bad measurement given to a filter."""


def as_matrix(value: ArrayLike, name: str, shape: Optional[tuple[int, int]] = None, *,
              column: bool = False) -> NDArray[np.float64]:
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


def check_covariance(m: NDArray[np.float64], name: str, *, definite: bool = False,
                     tol: float = 1e-9) -> NDArray[np.float64]:
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


def is_invertible(M: NDArray[np.float64], rtol: float = 1e-12) -> bool:
    """
    Tell whether a small square matrix is numerically invertible.

    |det M| is compared with Hadamard's bound prod_i |row_i| (|det M| <= that bound, with
    equality for orthogonal rows), so the test does not depend on the scale of M.
    """
    if M.shape == (1, 1):
        return float(M[0, 0]) != 0.0
    det, bound = float(np.linalg.det(M)), float(np.prod(np.linalg.norm(M, axis=1)))
    return bound > 0 and abs(det) > rtol * bound


def _smallest_eigenvalue(a: Any, b: Any, c: Any) -> Any:
    """
    Return the smallest eigenvalue of [[a, b], [b, c]], of floats or of arrays of them.

    (a + c) / 2 - sqrt(((a - c) / 2)^2 + b^2), with (a - c) * (a - c), not ** 2, which
    raises OverflowError past 1e154 on floats.
    """
    h = (a - c) / 2
    return (a + c) / 2 - (h * h + b * b) ** 0.5


def is_psd(P: NDArray[np.float64], tol: float = 1e-9) -> bool:
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
        return bool(_smallest_eigenvalue(a, b, c) >= -tol * max(1.0, abs(a), abs(c)))
    eps = tol * max(1.0, float(np.max(np.abs(np.diag(P)))))
    try:
        np.linalg.cholesky(P + eps * np.eye(n))
    except np.linalg.LinAlgError:
        return False
    return True


def psd_stack(P: NDArray[np.float64], tol: float = 1e-9) -> NDArray[np.bool_]:
    """Return `is_psd` of each P[k] of a stack (K, n, n): vectorised up to 2 x 2."""
    n = P.shape[1]
    if n > 2:
        return np.array([is_psd(M, tol) for M in P], dtype=bool)
    a, c = P[:, 0, 0], P[:, -1, -1]
    scale = np.maximum(np.maximum(1.0, np.abs(a)), np.abs(c))
    with np.errstate(over='ignore', invalid='ignore'):
        smallest = a if n == 1 else _smallest_eigenvalue(a, P[:, 0, 1], c)
        return np.asarray(smallest >= -tol * scale)


def as_vector(value: ArrayLike, size: int, name: str) -> NDArray[np.float64]:
    """Return value as a finite float vector of `size` entries; a float64 vector is not copied."""
    if value.__class__ is float:
        if size != 1 or not math.isfinite(value):
            return as_vector(np.array((value,)), size, name)
        return np.array((value,))
    elif value.__class__ is np.ndarray and value.dtype is FLOAT64:
        v = value.reshape(-1)
    else:
        try:
            v = np.array(value, dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise FilterError(f'{name} is not numeric: {exc}') from None
    if v.shape != (size,):
        raise FilterError(f'{name} must have {size} entries, got {v.size}')
    # a sum is finite when every entry is; only a sum that is not needs the full check
    if not math.isfinite(v.sum()) and not np.isfinite(v).all():
        raise FilterError(f'{name} has non-finite entries: {v}')
    return v
