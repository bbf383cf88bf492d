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
Theorem 2 of Fang & de Callafon 2011 for scalar systems: bounds on the peak covariance.

    (22) f(Y) = a Y a + q        (23) g(X) = X - X c (c X c + r)^-1 c X
    (24)-(25) the fixed points of X = f^k(g(X)) for the shortest and longest intervals
"""

import math

import numpy as np

from tskf_ros.core.irregular.common import interval, IrregularError, LOG_OVERFLOW


def scalar_peak_map(a: float, c: float, q: float, r: float, kappa: int, X: float) -> float:
    """f^kappa(g(X)), eqs. (22)-(23) for n = 1: the peak covariance one interval later."""
    # (23) g(X) = X - X c (c X c + r)^-1 c X = r X / (c^2 X + r)
    Y = r * X / (c * c * X + r)
    for _ in range(interval(kappa)):
        # (22) f(Y) = a Y a + q
        Y = a * a * Y + q
    return Y


def scalar_fixed_point(a: float, c: float, q: float, r: float, kappa: int) -> float:
    """
    Return the unique non-negative solution of X = f^kappa(g(X)) (closed form).

    f^kappa(Y) = a^{2 kappa} Y + q_kappa with q_kappa = q sum_{i<kappa} a^{2i}, so the
    equation is c^2 X^2 + b X - q_kappa r = 0 with b = r (1 - a^{2 kappa}) - q_kappa c^2;
    the root is taken in the form that does not cancel.
    """
    kappa = interval(kappa)
    a, c, q, r = float(a), float(c), float(q), float(r)
    if not r > 0 or q < 0:
        raise IrregularError(f'need r > 0 and q >= 0, got r = {r}, q = {q}')
    if c == 0 and abs(a) >= 1:
        raise IrregularError('c = 0 with |a| >= 1: (a, c) is not detectable (A1)')
    if abs(a) > 1 and 2 * kappa * math.log(abs(a)) > LOG_OVERFLOW:
        # a^{2 kappa} overflows: the peak covariance after such an interval is beyond any
        # float (X ~ a^{2 kappa} (r / c^2 + q / (a^2 - 1))), so the bound is +inf
        return math.inf
    a2k = a ** (2 * kappa)
    qk = q * kappa if a * a == 1 else q * (a2k - 1) / (a * a - 1)
    if c == 0:
        return qk / (1 - a2k)
    c2 = c * c
    b = r * (1 - a2k) - qk * c2
    root = np.sqrt(b * b + 4 * c2 * qk * r)
    return float((root - b) / (2 * c2) if b <= 0 else 2 * qk * r / (b + root))


def scalar_peak_bounds(a: float, c: float, q: float, r: float, tau: int,
                       eta: int) -> tuple[float, float]:
    """
    Theorem 2, eq. (25): (P_bar_tau, P_bar_eta), fixed points of X = f^k(g(X)), k = tau, eta.

    With intervals in [tau, eta] and a peak covariance started in [P_bar_tau, P_bar_eta],
    every later peak covariance stays there, and its limit points too.  The proof asks
    |a| >= 1 (so that f^tau <= f^eta); for |a| < 1 the same holds on
    [0, q / (1 - a^2)], which contains both fixed points.
    """
    tau, eta = interval(tau), interval(eta)
    if tau > eta:
        raise IrregularError(f'need tau <= eta, got tau = {tau}, eta = {eta}')
    return scalar_fixed_point(a, c, q, r, tau), scalar_fixed_point(a, c, q, r, eta)
