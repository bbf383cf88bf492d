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
Pointing metrics from the true pointing error: acquisition, re-acquisition, censoring.

In the cone: |phi| <= 15 deg (Section V).  Back in the cone: the first step from which
|phi| stays within the cone for HOLD_S seconds.  Acquisition: from the start of the run to
the first step back in the cone.  A re-acquisition event starts where |phi| leaves the
cone after the run was back in it (or, if the light is blocked at that step, where the
light is back), and lasts until |phi| is back in the cone.  An event still open at the end
of the run is censored at the time it was watched (the last step from which a hold could
still be seen); the distribution is the Kaplan-Meier estimate, and its percentiles are
read off it by linear interpolation between the event times (`km_quantile`).
"""

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from numpy.typing import NDArray

HOLD_S = 1.0                       # s |phi| must stay within the cone to count as back
HISTOGRAM_BIN_S = 0.25             # s: the acquisition histogram's bins
Bools = NDArray[np.bool_]


@dataclass(frozen=True)
class Durations:
    """Event durations (s) and whether each was seen to end (False: censored)."""

    times: NDArray[np.float64]
    observed: Bools

    @staticmethod
    def join(parts: Sequence['Durations']) -> 'Durations':
        """Concatenate several sets of events."""
        if not parts:
            return Durations(np.zeros(0), np.zeros(0, dtype=bool))
        return Durations(np.concatenate([p.times for p in parts]),
                         np.concatenate([p.observed for p in parts]))


def kaplan_meier(d: Durations) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """
    Return the distinct observed times t_j and the Kaplan-Meier survival S(t_j).

    S(t) = prod_{t_j <= t} (1 - d_j / n_j), d_j events ending at t_j, n_j events with a
    time >= t_j (one censored at t_j is still at risk there).
    """
    ended = np.unique(d.times[d.observed])
    if not ended.size:
        return ended, np.ones(0)
    order = np.sort(d.times)
    at_risk = order.size - np.searchsorted(order, ended, side='left')
    deaths = np.array([np.count_nonzero(d.times[d.observed] == t) for t in ended])
    return ended, np.cumprod(1.0 - deaths / at_risk)


def km_quantile(d: Durations, q: float) -> Optional[float]:
    """
    Return the q-quantile of the Kaplan-Meier distribution (None if it is not reached).

    F = 1 - S at the event times t_1 < t_2 < ...: t_1 if q <= F(t_1), else linearly
    interpolated between the two event times whose F bracket q.  Not reached when more
    than 1 - q of the mass is censored beyond the last event.
    """
    t, s = kaplan_meier(d)
    if not t.size:
        return None
    f = 1.0 - s
    if q > f[-1] + 1e-12:
        return None
    j = int(np.searchsorted(f, q - 1e-12, side='left'))
    if j == 0:
        return float(t[0])
    return float(t[j - 1] + (q - f[j - 1]) / (f[j] - f[j - 1]) * (t[j] - t[j - 1]))


def summary(d: Durations) -> dict:
    """Median, p90 (Kaplan-Meier, interpolated), event, ended and censored counts."""
    return {'median': km_quantile(d, 0.5), 'p90': km_quantile(d, 0.9),
            'events': int(d.times.size), 'ended': int(np.count_nonzero(d.observed)),
            'censored': int(np.count_nonzero(~d.observed))}


def _next(mask: Bools, none: int) -> NDArray[np.signedinteger]:
    """Per step k and run (columns): the first step >= k where mask is set (none: never)."""
    steps = np.arange(mask.shape[0], dtype=np.int32 if none < 2**31 else np.int64)
    index = np.where(mask, steps[:, None], steps.dtype.type(none))
    backward = index[::-1]
    np.minimum.accumulate(backward, axis=0, out=backward)
    return index


def pointing_events(phi: NDArray[np.float64], dt: float, *, angle: float,
                    dark: Optional[Bools] = None,
                    hold_s: float = HOLD_S) -> tuple[Durations, Durations]:
    """
    Return (acquisition, re-acquisition) durations of phi (steps, runs), in seconds.

    dark (steps,): the steps without light (a blocked beam); an event that starts in the
    dark starts when the light is back.  The events are listed run by run, each run's in
    time order; all runs take their next event at once.
    """
    steps, runs = phi.shape
    # a hold longer than the run is never seen (and hold_s / dt may be 1e300 or inf)
    hold_steps = hold_s / dt
    hold = max(int(round(hold_steps)), 1) if hold_steps < steps + 1 else steps + 1
    inside = np.abs(phi) <= angle
    dark = np.zeros(steps, dtype=bool) if dark is None else np.asarray(dark, dtype=bool)
    # the first lit step at or after each step (steps: none)
    lit = np.where(~dark, np.arange(steps), steps)
    next_lit = np.minimum.accumulate(np.r_[lit, steps][::-1])[::-1]
    last = steps - hold                 # the last step from which a hold can be seen
    # back in the cone at k: |phi| within it from k through k + hold - 1 (k = 0 .. last)
    c = np.concatenate([np.zeros((1, runs), dtype=np.int64), np.cumsum(inside, axis=0)])
    back = (c[hold:] - c[:-hold]) == hold if steps >= hold else np.zeros((0, runs), bool)
    none = back.shape[0]
    # the first step back in the cone at or after k (k = 0 .. last), and the first step
    # at or after k (k = 0 .. steps) where the run leaves the cone (steps: never)
    next_back = _next(back, none)
    leaves = np.zeros((steps + 1, runs), dtype=bool)
    leaves[1:steps] = inside[:-1] & ~inside[1:]
    next_leave = _next(leaves, steps)
    first = next_back[0] if none else np.full(runs, none)
    found = first < none
    acq_t = np.where(found, first * dt, (last + 1) * dt)
    # re-acquisitions: each round takes the next event of every run still watched
    events: list[tuple[NDArray[np.int64], NDArray[np.float64], Bools]] = []
    r = np.flatnonzero(found)
    k = first[r] + hold
    while r.size:
        leave = next_leave[k, r]
        r, leave = r[leave < steps], leave[leave < steps]
        start = next_lit[leave]
        late = start > last             # not watched long enough for a hold: censored at 0
        events.append((r[late], np.zeros(np.count_nonzero(late)), np.zeros(late.sum(), bool)))
        r, start = r[~late], start[~late]
        j = next_back[start, r]
        ended = j < none
        events.append((r[~ended], (last + 1 - start[~ended]) * dt,
                       np.zeros(np.count_nonzero(~ended), bool)))
        events.append((r[ended], (j[ended] - start[ended]) * dt,
                       np.ones(np.count_nonzero(ended), bool)))
        r, k = r[ended], j[ended] + hold
    run = np.concatenate([e[0] for e in events]) if events else np.zeros(0, np.int64)
    order = np.argsort(run, kind='stable')
    times = np.concatenate([e[1] for e in events])[order] if events else np.zeros(0)
    observed = np.concatenate([e[2] for e in events])[order] if events else np.zeros(0, bool)
    return (Durations(np.asarray(acq_t, dtype=float), found),
            Durations(times.astype(float), observed.astype(bool)))


def step_latency(phi: NDArray[np.float64], dt: float, locked: Bools, declared: Bools,
                 *, angle: float) -> Durations:
    """
    Return the supervisor's lock-window latency: from each declared loss to the next step tracking.

    locked (steps, runs): tracking and |phi| <= angle; a loss with no such later step is
    censored at the end of the run.  This measures the supervisor's own state changes
    (a held loss returns only after a clean lock window), not the pointing.
    """
    steps = phi.shape[0]
    index = np.where(locked, np.arange(steps)[:, None], steps)
    nxt = np.minimum.accumulate(index[::-1], axis=0)[::-1]
    k, r = np.nonzero(declared)
    ended = nxt[k, r] < steps
    times = np.where(ended, nxt[k, r] - k, steps - k) * dt
    return Durations(times.astype(float), ended)


def histogram(d: Durations, *, bin_s: float = HISTOGRAM_BIN_S, stop: float) -> dict:
    """Return the ended times binned from 0 to stop (s), and the censored count beside them."""
    edges = np.arange(0.0, stop + bin_s, bin_s)
    counts, _ = np.histogram(d.times[d.observed], bins=edges)
    return {'edges_s': [float(e) for e in edges], 'counts': [int(c) for c in counts],
            'censored': int(np.count_nonzero(~d.observed))}


__all__ = ['Durations', 'HISTOGRAM_BIN_S', 'histogram', 'HOLD_S', 'kaplan_meier',
           'km_quantile', 'pointing_events', 'step_latency', 'summary']
