"""
Fixed-lag smoother for the time-scale Kalman filter: x(t_{k-L}|t_k) as each point t_k arrives.

A window of the L + 1 newest points, fed one filter `StepResult` (and its jump F) at a
time; once full, each new point runs the RTS backward step of `tskf_ros.core.smoother`
(Rauch, Tung & Striebel 1965; Sarkka 2013, Theorem 8.2) from x(t_k|t_k) down to the
oldest point.  The output is delayed by L points: t_k - t_{k-L} = mu_{k-L} + ... + mu_{k-1}.
"""

from collections import deque
from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.matrices import as_matrix, FilterError
from tskf_ros.core.smoother import smoothed_step, smoother_gain
from tskf_ros.core.timescale_kalman import StepResult

Vector = NDArray[np.float64]
Matrix = NDArray[np.float64]

__all__ = ['FixedLagSmoother', 'Lagged']


class Lagged(NamedTuple):
    """The smoothed estimate of one point, given the points up to the newest."""

    point: int      # the point's number: 0 for the first StepResult added
    delay: float    # t_newest - t_point, the sum of the graininesses in between
    x: Vector       # x(t_point|t_newest)
    P: Matrix       # P(t_point|t_newest)


@dataclass(slots=True, frozen=True)
class _Point:
    """What the backward pass keeps of one point."""

    point: int
    mu: float
    x_f: Vector     # x(t_k|t_k)
    P_f: Matrix     # P(t_k|t_k)
    x_p: Vector     # x(t_{k+1}|t_k)
    P_p: Matrix     # P(t_{k+1}|t_k)
    G: Matrix       # the RTS gain of the jump to t_{k+1}


class FixedLagSmoother:
    """
    RTS smoothing over a sliding window of L + 1 points of a TimeScaleKalmanFilter run.

    A node that runs the filter step by step adds every result::

        res = kf.step(mu, y)
        F, _, _ = kf.transition_matrices(mu)
        out = smoother.add(res, F)        # None until L + 1 points have been added

    `out` is the estimate of the point L back, equal to the full `rts_smooth` over the
    points added so far.  Memory and time per point are O(L).  `flush` gives the last
    L points at the end of a stream.
    """

    def __init__(self, lag: int) -> None:
        if isinstance(lag, bool) or not isinstance(lag, (int, np.integer)) or lag < 0:
            raise FilterError(f'lag must be a whole number of points >= 0, got {lag!r}')
        self.lag = int(lag)
        self._window: deque[_Point] = deque(maxlen=self.lag + 1)
        self._added = 0

    def __len__(self) -> int:
        """Return the number of points in the window."""
        return len(self._window)

    def add(self, result: StepResult, F: ArrayLike) -> Lagged | None:
        """
        Add the filter's step at the newest point and its jump F (I + mu A or e^{A mu}).

        Return the smoothed estimate of the point `lag` back, or None while fewer than
        lag + 1 points have been added.
        """
        n = result.x_corrected.shape[0]
        F_ = as_matrix(F, 'F')
        if F_.shape != (n, n):
            raise FilterError(f'F must have shape {(n, n)} to match the step, got {F_.shape}')
        if self._window and self._window[-1].x_f.shape[0] != n:
            raise FilterError(f'the step has {n} states, the window '
                              f'{self._window[-1].x_f.shape[0]}')
        mu = float(result.mu)
        if not (math.isfinite(mu) and mu > 0):
            raise FilterError(f'the step has mu = {mu}: a graininess must be finite and > 0')
        P_f, P_p = np.array(result.P_corrected), np.array(result.P_predicted)
        self._window.append(_Point(self._added, mu, np.array(result.x_corrected), P_f,
                                   np.array(result.x_predicted), P_p,
                                   smoother_gain(P_f, F_, P_p)))
        self._added += 1
        if len(self._window) <= self.lag:
            return None
        return self._smooth()[0]

    def flush(self) -> list[Lagged]:
        """Return the points not yet output, oldest first, smoothed on the window; empty it."""
        # a full window has output its oldest point already
        done = 1 if len(self._window) == self.lag + 1 else 0
        out = self._smooth(every=True)[done:] if self._window else []
        self._window.clear()
        return out

    def _smooth(self, every: bool = False) -> list[Lagged]:
        """Run the backward pass over the window: its oldest point, or every point."""
        newest = self._window[-1]
        x, P, delay = newest.x_f, newest.P_f, 0.0
        out = [Lagged(newest.point, delay, x, P)]
        points = reversed(self._window)
        next(points)
        # x(t_k|T) from x(t_{k+1}|T), newest to oldest; T is the newest point
        for pt in points:
            x, P = smoothed_step(pt.x_f, pt.P_f, pt.x_p, pt.P_p, pt.G, x, P)
            delay += pt.mu
            if every:
                out.append(Lagged(pt.point, delay, x, P))
        if every:
            return out[::-1]
        return [Lagged(self._window[0].point, delay, x, P)]
