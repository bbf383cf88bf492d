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
Windows of the conical-scan EKF's samples filtered again, linearised where the smoother puts them.

The EKF linearises h at each prior.  In the first seconds the prior is several degrees
wide and often several degrees off, and what the Jacobian there misses leaks into the
drift estimate, which the lock then keeps (doc/design/two_axis.md, "The first samples
smoothed"); later updates move a right drift estimate off as well ("Smoothed again while
locked").  So the filter smooths its first smooth_after samples, then each later window of
smooth_every samples, from its estimate where the window begins (`ConicalEKFConfig`).
The iterated extended Kalman smoother (Bell, "The iterated Kalman smoother as a
Gauss-Newton method", SIAM J. Optimization, 1994) filters a window's samples again,
linearising each one at the previous pass's smoothed state (Rauch, Tung & Striebel, AIAA
J., 1965) instead of at the prior; its fixed point is the maximum a posteriori trajectory
of the samples (where the innovation clip does not act and the x1 floor does not bind:
both are the filter's own, kept in every pass).  The first pass linearises at the priors,
as the EKF did.  The estimate at the last sample of the last pass (filtered, which is also
smoothed there) replaces the EKF's.

`WindowRecord` keeps what the filter saw in a window (its prior at the window's first
sample; each step's graininess mu, input B u and jump F, each sample and its scan offset)
and the filter's own pass (its priors and posteriors); `smooth_window` takes that pass as
the first (or filters the window again from its prior, if a run was restarted in it: the
filter leaves such runs out, smoothing the others' record alone, `WindowRecord.only`), and
runs the others with the filter's predict (`propagate`) and update (`posterior`), and
`core.smoother`'s backward step.
"""

from dataclasses import dataclass, field
from typing import NamedTuple, Optional, Protocol

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core.smoother import smoothed_step_runs, smoother_gain_runs

FloatArray = NDArray[np.float64]

# passes of the smoother: the first linearises at the EKF's priors, each further one at
# the last pass's smoothed states (2, 3 and 5 passes: 16 runs lost at the end each at 1 V,
# seeds 100 to 199; doc/design/two_axis.md)
PASSES = 3


class Posterior(NamedTuple):
    """An update's result for each run: the posterior, and the first innovation and S."""

    x: FloatArray       # (runs, n); the prior where the sample is missing
    P: FloatArray       # (runs, n, n)
    y: FloatArray       # (runs,), 0 where missing
    S: FloatArray       # (runs,)


class Smoothable(Protocol):
    """A filter whose predict and update are pure functions of (x, P) (`ConicalScanEKF`)."""

    def propagate(self, x: FloatArray, P: FloatArray, mu: float, Bu: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return (x, P, F) predicted over mu nominal steps with the input B u."""

    def posterior(self, x: FloatArray, P: FloatArray, z: FloatArray, offset: FloatArray,
                  nominal: Optional[tuple[FloatArray, FloatArray]] = None) -> Posterior:
        """Update with z at the scan offset, h linearised at nominal (default: the prior)."""


@dataclass
class WindowRecord:
    """
    What a filter saw in a window, and its own pass over it.

    Its prior at the first sample; every step's mu, B u and jump F, each sample z and its
    scan offset; and the filter's priors x(k|k-1), P(k|k-1) and posteriors x(k|k), P(k|k),
    which are the smoother's first pass as they stand (the filter linearised at its priors)
    unless a run was restarted in the window (`smooth_window`).
    """

    # the prior at the window's start (runs, n): before the first sample's predict, if one
    # is noted; the filter begins its windows at an update, where it is x_p[0] (kept so
    # that a record may begin before a predict, and for a window with no sample yet)
    x0: FloatArray
    P0: FloatArray                                  # (runs, n, n)
    mu: list[Optional[float]] = field(default_factory=list)   # None: no predict before z
    Bu: list[Optional[FloatArray]] = field(default_factory=list)
    F: list[FloatArray] = field(default_factory=list)         # the jump into sample k
    z: list[FloatArray] = field(default_factory=list)         # NaN: missing
    offset: list[FloatArray] = field(default_factory=list)    # (runs, 2)
    x_p: list[FloatArray] = field(default_factory=list)       # the filter's x(k|k-1)
    P_p: list[FloatArray] = field(default_factory=list)
    x_f: list[FloatArray] = field(default_factory=list)       # the filter's x(k|k)
    P_f: list[FloatArray] = field(default_factory=list)
    # runs started afresh in the window (a hand-over): their record is not one filter's
    restarted: NDArray[np.bool_] = field(init=False)
    _pending: Optional[tuple[float, FloatArray, FloatArray]] = None

    def __post_init__(self) -> None:
        """Copy the prior; no run has been restarted."""
        self.x0, self.P0 = np.array(self.x0, dtype=float), np.array(self.P0, dtype=float)
        self.restarted = np.zeros(self.x0.shape[0], dtype=bool)

    @property
    def count(self) -> int:
        """Return the number of samples recorded."""
        return len(self.z)

    def only(self, runs: NDArray[np.bool_]) -> 'WindowRecord':
        """Return the record of the runs in the mask `runs` alone (a copy; none restarted)."""
        part = WindowRecord(self.x0[runs], self.P0[runs])
        part.mu, part.F = list(self.mu), list(self.F)
        part.Bu = [None if Bu is None else Bu[runs] for Bu in self.Bu]
        for name in ('z', 'offset', 'x_p', 'P_p', 'x_f', 'P_f'):
            setattr(part, name, [value[runs] for value in getattr(self, name)])
        if self._pending is not None:
            mu, Bu, F = self._pending
            part._pending = (mu, Bu[runs], F)
        return part

    def predicted(self, mu: float, Bu: FloatArray, F: FloatArray) -> None:
        """Note a predict over mu nominal steps with the input B u (runs, n) and jump F."""
        self._pending = (float(mu), np.array(Bu, dtype=float), np.array(F, dtype=float))

    def updated(self, z: FloatArray, offset: FloatArray, prior: tuple[FloatArray, FloatArray],
                posterior: tuple[FloatArray, FloatArray]) -> None:
        """Note a sample z (runs,) taken at the scan offset (2,) or (runs, 2), and the update."""
        n = self.x0.shape[1]
        if self._pending is None:
            mu, Bu, F = None, None, np.eye(n)
        else:
            mu, Bu, F = self._pending
        self._pending = None
        self.mu.append(mu)
        self.Bu.append(Bu)
        self.F.append(F)
        self.z.append(np.array(z, dtype=float))
        self.offset.append(np.array(np.broadcast_to(offset, (self.x0.shape[0], 2)),
                                    dtype=float))
        for into, value in zip((self.x_p, self.P_p, self.x_f, self.P_f), (*prior, *posterior)):
            into.append(np.array(value, dtype=float))


class _Forward(NamedTuple):
    x_f: FloatArray     # x(k|k) (K, runs, n)
    P_f: FloatArray
    x_p: FloatArray     # x(k|k-1); row 0 the prior
    P_p: FloatArray
    F: list[FloatArray]  # the jump into point k; F[0] unused


def _recorded(record: WindowRecord) -> _Forward:
    """Return the filter's own pass over the record: the smoother's first, if no run restarted."""
    return _Forward(np.stack(record.x_f), np.stack(record.P_f), np.stack(record.x_p),
                    np.stack(record.P_p), record.F)


def _forward(filt: Smoothable, record: WindowRecord,
             nominal: Optional[tuple[FloatArray, FloatArray]]) -> _Forward:
    """
    Filter the record again, sample k linearised at nominal[k] (None: at the prior).

    With nominal None it is the filter's own pass computed anew (for a restarted run, as if
    it had not been): the first pass of a window in which a run was restarted.
    """
    K, (runs, n) = record.count, record.x0.shape
    x_f, x_p = np.empty((K, runs, n)), np.empty((K, runs, n))
    P_f, P_p = np.empty((K, runs, n, n)), np.empty((K, runs, n, n))
    F: list[FloatArray] = []
    x, P = record.x0, record.P0
    for k in range(K):
        mu, Bu = record.mu[k], record.Bu[k]
        if mu is None or Bu is None:
            F.append(np.eye(n))
        else:
            x, P, F_k = filt.propagate(x, P, mu, Bu)
            F.append(F_k)
        x_p[k], P_p[k] = x, P
        at = None if nominal is None else (nominal[0][k], nominal[1][k])
        post = filt.posterior(x, P, record.z[k], record.offset[k], at)
        x, P = post.x, post.P
        x_f[k], P_f[k] = x, P
    return _Forward(x_f, P_f, x_p, P_p, F)


def _backward(fw: _Forward) -> tuple[FloatArray, FloatArray]:
    """Return the RTS smoothed x(k|K), P(k|K) of a forward pass (`core.smoother`'s step)."""
    xs, Ps = fw.x_f.copy(), fw.P_f.copy()
    for k in range(len(xs) - 2, -1, -1):
        G = smoother_gain_runs(np.ascontiguousarray(fw.P_f[k]), fw.F[k + 1],
                               np.ascontiguousarray(fw.P_p[k + 1]))
        xs[k], Ps[k] = smoothed_step_runs(fw.x_f[k], fw.P_f[k], fw.x_p[k + 1],
                                          fw.P_p[k + 1], G, xs[k + 1], Ps[k + 1])
    return xs, Ps


def smooth_window(filt: Smoothable, record: WindowRecord, passes: int = PASSES
                  ) -> tuple[FloatArray, FloatArray]:
    """
    Return (x, P) at the record's last sample after `passes` passes of the smoother.

    Pass 1 is the EKF's own, as recorded (h linearised at each prior; filtered again from
    the record's prior if a run was restarted in it); pass i > 1 filters the record again,
    sample k linearised at pass i - 1's smoothed x(k|K), P(k|K).  With passes 1 it returns
    the filter's own estimate (for a run restarted in the window, what the filter would
    have had without the restart, which `ConicalScanEKF.update` does not take).
    """
    if record.count == 0:
        return record.x0.copy(), record.P0.copy()
    nominal: Optional[tuple[FloatArray, FloatArray]] = None
    # a run restarted in the window has a recorded pass that jumps at the restart, which
    # the backward pass cannot take (its covariances are then not positive definite, and
    # a sigma-point linearisation's Cholesky factor fails): the window is then filtered
    # again from its prior, one history per run
    fw = _forward(filt, record, None) if record.restarted.any() else _recorded(record)
    for _ in range(passes - 1):
        nominal = _backward(fw)
        del fw                  # one forward pass and the smoothed states at a time
        fw = _forward(filt, record, nominal)
    return fw.x_f[-1].copy(), fw.P_f[-1].copy()
