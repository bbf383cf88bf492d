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
The points of the time scale kept for rewinding, and the re-run after a late sample.

Every point t_k keeps its predictor xhat(t_k), P(t_k) and the input in force on
[t_k, sigma(t_k)).  A late sample at t with t_j < t < t_{j+1} becomes a point, which
changes mu(t_j) = t - t_j; the filter is re-run from t_j:

    step(mu(t_j), y(t_j)), step(mu(t), y(t)), step(mu(t_{j+1}), y(t_{j+1})), ...

(Bohner & Wintz Table 3), the cost growing with the lateness, not with the history.
"""

from collections import deque
from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional

import numpy as np

from tskf_ros.core.timescale_kalman import TimeScaleKalmanFilter
from tskf_ros.owc.session.outcome import FloatArray, Outcome, Reading


@dataclass(slots=True)
class Point:
    """A point of the time scale: a measurement, an input, or both."""

    stamp_ns: int
    y: Optional[Reading]       # None: input only
    x: FloatArray              # the predictor at this point (before stepping from it)
    P: FloatArray
    u: FloatArray              # the input in force on [t, sigma(t))
    has_input: bool = False    # an input sample has this stamp
    variance: float = 0.0      # the sample's own variance (use_message_variance)


# step(point, sigma_ns, revised, out): the filter stepped from point to sigma_ns (its
# predictor now kf.x, kf.P), the estimates and mu added to out; returns trace P
StepFunction = Callable[[Point, int, bool, Outcome], float]


class Rewind(NamedTuple):
    """The points taken off the history for a late sample, and those to re-run."""

    tail: list[Point]       # points[j:] as they were, put back if the re-run is refused
    rerun: list[Point]      # the left neighbour t_j, the late point (unless merged), the rest
    new: int                # the late point's index in rerun
    has_prior: bool         # the late point has a predictor to gate against (not points[0])


class History:
    """The newest points: at most `size`, and those within `window_ns` of the newest."""

    def __init__(self, size: int, window_ns: float) -> None:
        self.points: deque[Point] = deque(maxlen=size)     # the oldest drop out
        self.window_ns = window_ns

    def resize(self, size: int, window_ns: float) -> None:
        """Keep at most `size` points (the newest) and the newest window_ns from now on."""
        if size != self.points.maxlen:
            self.points = deque(self.points, maxlen=size)
        self.window_ns = window_ns

    def trim(self) -> None:
        """Keep the newest window_ns of points plus the one before."""
        points, window_ns = self.points, self.window_ns
        while len(points) > 2 and points[-1].stamp_ns - points[1].stamp_ns > window_ns:
            points.popleft()

    def index(self, stamp_ns: int) -> int:
        """Return the index of the first point at or after stamp_ns, scanning from the newest."""
        i = len(self.points)
        for point in reversed(self.points):
            if point.stamp_ns < stamp_ns:
                break
            i -= 1
        return i

    def rewind(self, stamp_ns: int, y: Reading, variance: float, i: int) -> Rewind:
        """
        Take the points from the late sample's left neighbour t_j on off the history.

        The late sample goes before points[i]: j = i - 1, or j = i when it has the stamp
        of points[i], an input-only point, into which it merges.  A new point takes the
        input in force at t_j (zero-order hold).  Only points[j:] are taken off.
        """
        points = self.points
        merged = i < len(points) and points[i].stamp_ns == stamp_ns
        j = i if merged else i - 1
        tail = [points.pop() for _ in range(len(points) - j)]
        tail.reverse()
        left = tail[0]
        if merged:
            rerun = [Point(left.stamp_ns, y, left.x, left.P, left.u, left.has_input,
                           variance)] + tail[1:]
        else:
            rerun = [left, Point(stamp_ns, y, np.zeros(0), np.zeros((0, 0)), left.u,
                                 variance=variance)] + tail[1:]
        new = 0 if merged else 1
        return Rewind(tail, rerun, new, j + new > 0)

    @staticmethod
    def rerun(rewind: Rewind, kf: TimeScaleKalmanFilter, step: StepFunction,
              out: Outcome) -> None:
        """
        Re-run kf through the re-run points from the left neighbour's predictor.

        Each point gets its new predictor; raises as step does.
        """
        rerun = rewind.rerun
        kf.x, kf.P = rerun[0].x, rerun[0].P
        for k in range(len(rerun) - 1):
            nxt = rerun[k + 1]
            step(rerun[k], nxt.stamp_ns, True, out)
            rerun[k + 1] = Point(nxt.stamp_ns, nxt.y, kf.x, kf.P, nxt.u, nxt.has_input,
                                 nxt.variance)

    def put_back(self, rewind: Rewind) -> None:
        """Undo rewind: the history as it was."""
        self.points.extend(rewind.tail)

    def commit(self, rewind: Rewind) -> None:
        """Keep the re-run points."""
        self.points.extend(rewind.rerun)

    def measured_around(self, rewind: Rewind) -> tuple[Optional[int], Optional[int]]:
        """Return the stamps of the measurement points around the late one (before commit)."""
        rerun, new = rewind.rerun, rewind.new
        after = next((p.stamp_ns for p in rerun[new + 1:] if p.y is not None), None)
        before = next((p.stamp_ns for p in reversed(rerun[:new]) if p.y is not None), None)
        if before is None:      # the points left on the history come before the re-run
            before = next((p.stamp_ns for p in reversed(self.points) if p.y is not None), None)
        return before, after
