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

"""Theorem 2 of Fang & de Callafon 2011: the scalar peak-covariance bounds (22)-(25)."""

import math

import numpy as np
import pytest

from tskf_ros.core import irregular as ir


def peak_map(a, c, q, r, kappa, X):
    """f^kappa(g(X)) written here: g in information form (1/X + c^2/r)^-1, f(Y) = a^2 Y + q."""
    Y = 1.0 / (1.0 / X + c * c / r)
    for _ in range(kappa):
        Y = a * a * Y + q
    return Y


def test_scalar_fixed_points_hand_numbers():
    # a = 1.2, c = q = r = 1, k = 1: X^2 - 1.44 X - 1 = 0
    lo, hi = ir.scalar_peak_bounds(1.2, 1.0, 1.0, 1.0, 1, 4)
    assert lo == pytest.approx((1.44 + np.sqrt(1.44 ** 2 + 4)) / 2, rel=1e-12)
    assert hi == pytest.approx(peak_map(1.2, 1.0, 1.0, 1.0, 4, hi), rel=1e-12)
    # the module's map (eq. (22)-(23) as printed) agrees with the information form
    for X in (0.1, 1.0, 17.0):
        assert ir.scalar_peak_map(1.2, 1.0, 1.0, 1.0, 3, X) == pytest.approx(
            peak_map(1.2, 1.0, 1.0, 1.0, 3, X), rel=1e-12)
    assert hi == pytest.approx(11.454149197572, rel=1e-10)
    # a = 1: q_k = k q; X^2 - 2 X - 2 = 0 for k = 2
    assert ir.scalar_fixed_point(1.0, 1.0, 1.0, 1.0, 2) == pytest.approx(1 + np.sqrt(3))
    with pytest.raises(ir.IrregularError):
        ir.scalar_fixed_point(1.5, 0.0, 1.0, 1.0, 2)


# README's table (bounds and the peaks seen on 5 sequences of 30 intervals, seed 7), to the
# printed digits: (a, c, q, r, tau, eta), (bounds), (peaks seen), half a printed unit
@pytest.mark.parametrize('a, c, q, r, tau, eta, bounds, seen, tol', [
    (1.3, 1.0, 1.0, 2.0, 1, 5, (3.038, 44.927), (3.103, 44.925), 5e-4),
    (1.0, 0.7, 0.5, 1.0, 2, 6, (2.014, 4.394), (2.035, 4.392), 5e-4),
    (-1.1, 2.0, 0.3, 0.5, 1, 3, (0.4163, 1.3043), (0.4163, 1.3043), 5e-5),
    (0.8, 1.0, 1.0, 1.0, 1, 4, (1.370, 2.431), (1.371, 2.431), 5e-4),   # stable a
])
def test_peak_covariances_stay_within_theorem2_bounds(a, c, q, r, tau, eta, bounds, seen, tol):
    rng = np.random.default_rng(7)
    lo, hi = ir.scalar_peak_bounds(a, c, q, r, tau, eta)
    # fixed points of the map written in this file
    assert peak_map(a, c, q, r, tau, lo) == pytest.approx(lo, rel=1e-11)
    assert peak_map(a, c, q, r, eta, hi) == pytest.approx(hi, rel=1e-11)
    assert (lo, hi) == pytest.approx(bounds, abs=tol * 1.01)
    all_peaks = []
    for _ in range(5):
        gaps = rng.integers(tau, eta + 1, size=30)
        times = np.concatenate([[0], np.cumsum(gaps)])
        y = np.full((times[-1] + 1, 1), np.nan)
        y[times, 0] = 0.0
        P0 = rng.uniform(lo, hi)
        sw = ir.run_switching([[a]], [[c]], Q=[[q]], R=[[r]], x0=[0.0], P0=[[P0]], y=y)
        peaks = sw.P_prior[times, 0, 0]
        all_peaks.extend(peaks)
        assert np.all(peaks >= lo * (1 - 1e-12)) and np.all(peaks <= hi * (1 + 1e-12))
        # eq. (24): sandwiched by the single-rate sequences from ordered starts
        p_tau, p_eta = 0.5 * P0, 2 * P0
        for k, peak in zip(gaps, peaks[1:]):
            p_tau = peak_map(a, c, q, r, tau, p_tau)
            p_eta = peak_map(a, c, q, r, eta, p_eta)
            assert p_tau <= peak * (1 + 1e-12) and peak <= p_eta * (1 + 1e-12)
    assert (min(all_peaks), max(all_peaks)) == pytest.approx(seen, abs=tol * 1.01)


def test_scalar_fixed_point_for_a_huge_interval_is_inf_not_an_overflow():
    # closed form check for a small kappa, then the limit
    a, c, q, r = 2.0, 1.0, 1.0, 1.0
    X = ir.scalar_fixed_point(a, c, q, r, 3)
    # X = f^3(g(X)) with g(X) = r X / (c^2 X + r), f(Y) = a^2 Y + q
    Y = r * X / (c * c * X + r)
    for _ in range(3):
        Y = a * a * Y + q
    assert Y == pytest.approx(X, rel=1e-12)
    assert ir.scalar_fixed_point(a, c, q, r, 10**9) == math.inf
    # |a| < 1: a^{2 kappa} -> 0, so X = f^kappa(g(X)) -> q / (1 - a^2)
    assert ir.scalar_fixed_point(0.5, c, q, r, 10**9) == pytest.approx(
        q / (1 - 0.25), rel=1e-12)
