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
"""Pointing metrics from the true error: Kaplan-Meier against scipy, scripted events."""

import numpy as np
import pytest
import scipy.stats

from tskf_ros.experiments import pointing_metrics as pm


def durations(times, observed):
    return pm.Durations(np.asarray(times, dtype=float), np.asarray(observed, dtype=bool))


def test_kaplan_meier_equals_scipy_with_ties_and_censoring():
    rng = np.random.default_rng(3)
    for _ in range(20):
        n = int(rng.integers(5, 60))
        times = np.round(rng.exponential(2.0, n), 1)     # ties on purpose
        observed = rng.random(n) < 0.7
        observed[0] = True
        t, s = pm.kaplan_meier(durations(times, observed))
        ref = scipy.stats.ecdf(scipy.stats.CensoredData(uncensored=times[observed],
                                                        right=times[~observed]))
        np.testing.assert_allclose(s, ref.sf.evaluate(t), rtol=1e-12, atol=1e-15)


def test_quantiles_interpolate_between_event_times():
    # the old rule published [3.15, 1.00] as median 1.00, p90 1.00; F = 0.5 at 1.00 and
    # 1 at 3.15, so p90 = 1 + (0.9 - 0.5) / 0.5 * 2.15
    d = durations([3.15, 1.0], [True, True])
    assert pm.km_quantile(d, 0.5) == pytest.approx(1.0, abs=1e-12)
    assert pm.km_quantile(d, 0.9) == pytest.approx(1.0 + 0.8 * 2.15, abs=1e-12)
    assert pm.summary(d) == {'median': pytest.approx(1.0), 'p90': pytest.approx(2.72),
                             'events': 2, 'ended': 2, 'censored': 0}
    # uncensored: F(t) is the empirical cdf, interpolated linearly between the order
    # statistics; on 1..10 the q-quantile is 10 q
    d = durations(np.arange(1.0, 11.0), np.ones(10, dtype=bool))
    for q in (0.1, 0.25, 0.5, 0.9, 1.0):
        assert pm.km_quantile(d, q) == pytest.approx(10.0 * q, abs=1e-12)


def test_censored_mass_beyond_the_last_event_is_not_reached():
    d = durations([1.0, 2.0, 5.0, 5.0], [True, True, False, False])
    assert pm.km_quantile(d, 0.5) == pytest.approx(2.0)
    assert pm.km_quantile(d, 0.9) is None
    assert pm.summary(durations([], [])) == {'median': None, 'p90': None, 'events': 0,
                                             'ended': 0, 'censored': 0}


def test_events_of_a_scripted_run():
    # dt 0.1 s, hold 0.3 s (3 steps), cone 15 deg; run 0: in at once, leaves at step 4,
    # back at 7 (held 7-9), leaves at 12, back at 13 only for 2 steps, back at 16 for good;
    # run 1: out until step 5; leaves at 18, never back (censored at the last watched step)
    out, inn = 30.0, 0.0
    run0 = [inn] * 4 + [out] * 3 + [inn] * 5 + [out] + [inn] * 2 + [out] + [inn] * 4
    run1 = [out] * 5 + [inn] * 13 + [out] * 2
    phi = np.array([run0, run1]).T
    acq, re = pm.pointing_events(phi, 0.1, angle=15.0, hold_s=0.3)
    np.testing.assert_allclose(acq.times, [0.0, 0.5], atol=1e-12)
    assert acq.observed.tolist() == [True, True]
    # run 0: 4 -> 7 (0.3 s), 12 -> 16 (0.4 s: 13-14 is not a hold); run 1: 18, censored
    # at the last step a hold could start from (20 - 3 = 17): (17 + 1 - 18) steps
    np.testing.assert_allclose(re.times, [0.3, 0.4, 0.0], atol=1e-12)
    assert re.observed.tolist() == [True, True, False]


@pytest.mark.parametrize('dt', [3.05e-230, 5e-324, 1e-3])
def test_a_hold_longer_than_the_run_is_never_seen(dt):
    # hold_s / dt beyond the run's 20 steps (or beyond any int): nothing is acquired,
    # every run censored at time 0, as for any run shorter than its hold; no overflow
    phi = np.zeros((20, 3))
    acq, re = pm.pointing_events(phi, dt, angle=15.0, hold_s=1.0)
    assert acq.observed.tolist() == [False] * 3
    np.testing.assert_allclose(acq.times, 0.0, atol=1e-300)
    assert re.times.size == 0


def test_an_event_in_the_dark_starts_when_the_light_is_back():
    # out at step 3 in the dark (2-6), back in the cone at 8: 1 step after the light (7)
    phi = np.array([[0, 0, 0, 30, 30, 30, 30, 30, 0, 0, 0, 0, 0]], dtype=float).T
    dark = np.zeros(13, dtype=bool)
    dark[2:7] = True
    _, re = pm.pointing_events(phi, 0.5, angle=15.0, dark=dark, hold_s=1.0)
    np.testing.assert_allclose(re.times, [0.5], atol=1e-12)
    _, re = pm.pointing_events(phi, 0.5, angle=15.0, hold_s=1.0)
    np.testing.assert_allclose(re.times, [2.5], atol=1e-12)


def test_never_acquired_is_censored_and_the_histogram_counts_it():
    phi = np.full((10, 3), 40.0)
    phi[6:, 0] = 0.0
    acq, re = pm.pointing_events(phi, 1.0, angle=15.0, hold_s=2.0)
    assert acq.observed.tolist() == [True, False, False] and acq.times[0] == 6.0
    assert re.times.size == 0
    h = pm.histogram(acq, bin_s=2.0, stop=10.0)
    assert h == {'edges_s': [0.0, 2.0, 4.0, 6.0, 8.0, 10.0], 'counts': [0, 0, 0, 1, 0],
                 'censored': 2}


def test_lock_window_latency_is_from_the_declared_loss():
    locked = np.array([[1, 1], [0, 1], [0, 1], [1, 1], [1, 1]], dtype=bool)
    declared = np.zeros((5, 2), dtype=bool)
    declared[1, 0] = declared[4, 1] = True
    d = pm.step_latency(np.zeros((5, 2)), 0.5, locked, declared, angle=15.0)
    np.testing.assert_allclose(sorted(d.times), [0.0, 1.0])
    assert d.observed.all()
    locked[3:, 0] = False
    d = pm.step_latency(np.zeros((5, 2)), 0.5, locked, declared, angle=15.0)
    # never tracking again: censored at the end of the run (4 steps after the loss)
    assert d.observed.tolist() == [False, True] and d.times[0] == pytest.approx(2.0)


def reference_events(inside, dt, hold, dark):
    """Return the events of one run, step by step: the definitions written out again."""
    steps = inside.size
    last = steps - hold
    back = [k for k in range(last + 1) if inside[k:k + hold].all()]
    if not back:
        return (max(last + 1, 0) * dt, False), []   # a run shorter than its hold: 0
    events, k = [], back[0] + hold
    while True:
        leave = next((s for s in range(max(k, 1), steps) if inside[s - 1] and not inside[s]),
                     None)
        if leave is None:
            break
        start = next((s for s in range(leave, steps) if not dark[s]), steps)
        if start > last:
            events.append((0.0, False))
            break
        again = next((b for b in back if b >= start), None)
        if again is None:
            events.append(((last + 1 - start) * dt, False))
            break
        events.append(((again - start) * dt, True))
        k = again + hold
    return (back[0] * dt, True), events


def test_events_of_all_runs_at_once_are_each_runs_own():
    # random walks in and out of the cone, with and without dark steps: the events, run by
    # run in time order, are those of the step-by-step definition
    rng = np.random.default_rng(1)
    for trial in range(60):
        steps, runs = int(rng.integers(1, 50)), int(rng.integers(1, 9))
        phi = (np.cumsum(rng.normal(0.0, rng.uniform(1.0, 12.0), (steps, runs)), axis=0)
               + rng.uniform(-30.0, 30.0, runs))
        dark = rng.random(steps) < 0.3 if trial % 2 else np.zeros(steps, dtype=bool)
        dt, hold_s = float(rng.choice([0.1, 0.5])), float(rng.choice([0.1, 0.3, 1.0]))
        acq, re = pm.pointing_events(phi, dt, angle=15.0, dark=dark, hold_s=hold_s)
        hold = max(int(round(hold_s / dt)), 1)
        want = [reference_events(np.abs(phi[:, r]) <= 15.0, dt, hold, dark)
                for r in range(runs)]
        assert acq.times.tolist() == [w[0][0] for w in want]
        assert acq.observed.tolist() == [w[0][1] for w in want]
        events = [e for w in want for e in w[1]]
        assert re.times.tolist() == [e[0] for e in events]
        assert re.observed.tolist() == [e[1] for e in events]
