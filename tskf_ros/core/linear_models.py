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
The papers' linear models, truth simulation on a time scale, and an offline filter run.

Models:
- Bohner & Wintz Example 3.20 / Cai et al. system (1): spring-mass, A = [[0, 1], [-1, -2]],
  G = [0, 1]^T, C = [1, 0], w ~ N(0, 1), v ~ N(0, 2), x0 = [1, 1], P0 = diag(2, 3).
- Cai et al. system (3), the intermittent OWC link: x = theta (rad), x^Delta = x + w,
  y = -637.35 x + 511.97 + v (the linear part (2) of Fig. 5), w ~ N(0, 1), v ~ N(0, 100).

Truth: x(sigma) = (I + mu A) x + mu G w, y = C x + D + v, with 'theory' noise scaling
(Var(mu G w) = mu G Q G^T, Var(v) = R / mu) or 'unit' (doc/design/core.md).
"""

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.matrices import as_matrix
from tskf_ros.core.time_scales import TimeScale
from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter

NOISE_SCALINGS = ('theory', 'unit')
FloatArray = NDArray[np.float64]


@dataclass
class LinearModel:
    """x^Delta = A x + B u + G w, y = C x + D + v on a time scale, with the filter's prior."""

    name: str
    A: FloatArray
    C: FloatArray
    Q: FloatArray
    R: FloatArray
    x0: FloatArray
    P0: FloatArray
    G: Optional[FloatArray] = None
    B: Optional[FloatArray] = None
    D: Optional[FloatArray] = None
    state_names: tuple[str, ...] = field(default_factory=tuple)

    def make_filter(self, transition: str = 'euler',
                    allow_nonregressive: bool = False) -> TimeScaleKalmanFilter:
        """Make a fresh TimeScaleKalmanFilter for this model."""
        return TimeScaleKalmanFilter(self.A, self.C, Q=self.Q, R=self.R, G=self.G, B=self.B,
                                     D=self.D, x0=self.x0, P0=self.P0, transition=transition,
                                     allow_nonregressive=allow_nonregressive)


def spring_mass() -> LinearModel:
    """Bohner & Wintz Example 3.20 (Cai et al. system (1) with B = D = 0)."""
    return LinearModel('spring_mass', A=np.array([[0.0, 1.0], [-1.0, -2.0]]),
                       C=np.array([[1.0, 0.0]]), G=np.array([[0.0], [1.0]]),
                       Q=np.array([[1.0]]), R=np.array([[2.0]]), x0=np.array([1.0, 1.0]),
                       P0=np.diag([2.0, 3.0]), state_names=('position', 'velocity'))


OWC_SLOPE = -637.35      # mW / rad, Cai eq. (2)
OWC_OFFSET = 511.97      # mW
OWC_LINEAR_RANGE = (0.4141, 0.6729)   # rad, where eq. (2) was fitted


def owc(a: float = 1.0, theta0: float = 0.5435, p0: float = 0.01) -> LinearModel:
    """Cai et al. system (3): x^Delta = a x + w, y = -637.35 x + 511.97 + v (a = 1 as printed)."""
    return LinearModel('owc', A=np.array([[a]]), C=np.array([[OWC_SLOPE]]),
                       G=np.array([[1.0]]), Q=np.array([[1.0]]), R=np.array([[100.0]]),
                       D=np.array([OWC_OFFSET]), x0=np.array([theta0]),
                       P0=np.array([[p0]]), state_names=('theta',))


def simulate_truth(model: LinearModel, ts: TimeScale, rng: 'np.random.Generator', *,
                   noise_scaling: str = 'theory', x_true0: Optional[ArrayLike] = None
                   ) -> tuple[FloatArray, FloatArray]:
    """
    Simulate the model on ts: x(sigma) = (I + mu A) x + mu B u + noise; y = C x + D + v.

    Returns (x, y) with x of shape (N, n) and y of shape (N, p).  The truth starts at
    x_true0 (default: drawn from N(x0, P0)).  The measurement at the last point uses
    the graininess of the point before it (it has no forward jump).
    """
    if noise_scaling not in NOISE_SCALINGS:
        raise ValueError(f'noise_scaling must be one of {NOISE_SCALINGS}, got {noise_scaling!r}')
    A = as_matrix(model.A, 'A')
    n = A.shape[0]
    C = as_matrix(model.C, 'C')
    G = np.eye(n) if model.G is None else as_matrix(model.G, 'G', column=True)
    D = np.zeros(C.shape[0]) if model.D is None else np.asarray(model.D, float).reshape(-1)
    Lq = np.linalg.cholesky(as_matrix(model.Q, 'Q'))
    Lr = np.linalg.cholesky(as_matrix(model.R, 'R'))
    mu = ts.mu()
    mu_meas = mu.copy()
    if mu.size > 1:
        mu_meas[-1] = mu[-2]
    N = len(ts)
    x = np.zeros((N, n))
    x[0] = (rng.multivariate_normal(model.x0, model.P0) if x_true0 is None
            else np.asarray(x_true0, float))
    for k in range(N - 1):
        w = Lq @ rng.standard_normal(Lq.shape[0])
        scale = np.sqrt(mu[k]) if noise_scaling == 'theory' else mu[k]
        x[k + 1] = x[k] + mu[k] * (A @ x[k]) + scale * (G @ w)
    vscale = 1.0 / np.sqrt(mu_meas) if noise_scaling == 'theory' else np.ones(N)
    v = (rng.standard_normal((N, C.shape[0])) @ Lr.T) * vscale[:, None]
    y = x @ C.T + D + v
    return x, y


def ou_angle(points: ArrayLike, rng: 'np.random.Generator', *, mean: float = 0.5435,
             std: float = 0.04, tau: float = 2.0) -> FloatArray:
    """
    Simulate a bounded vibration angle: an Ornstein-Uhlenbeck process sampled exactly at points.

    Used as the true theta for Cai's OWC model, whose printed dynamics x^Delta = x
    grow without bound (see README); clipped to the linear range of eq. (2).
    """
    t = np.asarray(points, float)
    th = np.empty(t.size)
    th[0] = mean + std * rng.standard_normal()
    for k in range(1, t.size):
        a = np.exp(-(t[k] - t[k - 1]) / tau)
        th[k] = mean + a * (th[k - 1] - mean) + std * np.sqrt(1 - a * a) * rng.standard_normal()
    return np.clip(th, *OWC_LINEAR_RANGE)


@dataclass
class FilterRun:
    """Estimates along a time scale: the paper's predictor and the corrected estimate."""

    t: FloatArray
    mu: FloatArray
    x_pred: FloatArray      # (N, n): xhat(t_k) from data up to t_{k-1} (Table 3)
    P_pred: FloatArray      # (N, n, n)
    x_corr: FloatArray      # (N, n): xhat(t_k | t_k), NaN at the last point (no mu yet)
    P_corr: FloatArray


def run_filter(model: LinearModel, ts: TimeScale, y: FloatArray, *,
               transition: str = 'euler', allow_nonregressive: bool = False) -> FilterRun:
    """Run the time-scale filter over ts with measurements y (NaN rows = missing)."""
    kf = model.make_filter(transition, allow_nonregressive)
    N, n = len(ts), kf.n
    mu = ts.mu()
    x_pred = np.zeros((N, n))
    P_pred = np.zeros((N, n, n))
    x_corr = np.full((N, n), np.nan)
    P_corr = np.full((N, n, n), np.nan)
    x_pred[0], P_pred[0] = kf.x, kf.P
    for k in range(N - 1):
        yk = None if np.any(np.isnan(y[k])) else y[k]
        kf.step(mu[k], yk)
        x_pred[k + 1], P_pred[k + 1] = kf.x, kf.P
        x_corr[k], P_corr[k] = kf.x_corrected, kf.P_corrected
    return FilterRun(ts.points, mu, x_pred, P_pred, x_corr, P_corr)
