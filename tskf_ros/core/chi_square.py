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
The chi-square distribution's cdf, survival function and upper quantile, without scipy.

For chi^2(nu), F(x) = P(nu / 2, x / 2), the regularized lower incomplete gamma function
(Abramowitz & Stegun 26.4.19), and the survival Q = 1 - P.  P(a, z) is evaluated by its
series for z < a + 1 and Q(a, z) by its continued fraction otherwise (Press, Teukolsky,
Vetterling & Flannery, Numerical Recipes, 3rd ed., section 6.2, eqs. (6.2.5) and
(6.2.7), Lentz's method), each to double precision.  The upper quantile x (Q(x) =
alpha) is found by Newton's method on log Q, kept inside a bracket by bisection.
`scipy.special.chdtr` and `chdtri` compute the same (test/core/test_chi_square.py);
this module exists so that a node's start does not import scipy.special (0.3 to 0.5 s).
"""

import math

EPS = 1e-16           # relative size of the last term kept in the series and fraction
TINY = 1e-300         # Lentz's guard against a zero denominator
MAX_TERMS = 10_000    # far beyond what a double needs for the arguments a node passes
XTOL = 1e-14          # relative tolerance of the quantile


def _log_prefactor(a: float, z: float) -> float:
    """log(z^a e^-z / Gamma(a)), common to the series and the fraction."""
    return a * math.log(z) - z - math.lgamma(a)


def _lower_series(a: float, z: float) -> float:
    """P(a, z) by its series, z < a + 1: e^-z z^a / Gamma(a + 1) sum z^n / (a+1)...(a+n)."""
    term = total = 1.0 / a
    for n in range(1, MAX_TERMS):
        term *= z / (a + n)
        total += term
        if abs(term) < abs(total) * EPS:
            break
    return total * math.exp(_log_prefactor(a, z))


def _upper_fraction(a: float, z: float) -> float:
    """Q(a, z) by its continued fraction, z >= a + 1 (modified Lentz)."""
    b = z + 1.0 - a
    c = 1.0 / TINY
    d = 1.0 / b
    h = d
    for i in range(1, MAX_TERMS):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = TINY if abs(d) < TINY else d
        c = b + an / c
        c = TINY if abs(c) < TINY else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < EPS:
            break
    return math.exp(_log_prefactor(a, z)) * h


def _check(nu: float, x: float) -> None:
    if not (math.isfinite(nu) and nu > 0.0):
        raise ValueError(f'chi-square degrees of freedom must be > 0, got {nu}')
    if math.isnan(x):
        raise ValueError('chi-square argument is NaN')


def cdf(nu: float, x: float) -> float:
    """Return P(chi^2(nu) <= x) (scipy.special.chdtr(nu, x))."""
    _check(nu, x)
    if x <= 0.0:
        return 0.0
    if math.isinf(x):
        return 1.0
    a, z = 0.5 * nu, 0.5 * x
    return _lower_series(a, z) if z < a + 1.0 else 1.0 - _upper_fraction(a, z)


def sf(nu: float, x: float) -> float:
    """Return P(chi^2(nu) > x) (scipy.special.chdtrc(nu, x)), accurate in the far tail."""
    _check(nu, x)
    if x <= 0.0:
        return 1.0
    if math.isinf(x):
        return 0.0
    a, z = 0.5 * nu, 0.5 * x
    return 1.0 - _lower_series(a, z) if z < a + 1.0 else _upper_fraction(a, z)


def isf(alpha: float, nu: float) -> float:
    """Return x with P(chi^2(nu) > x) = alpha (scipy.special.chdtri(nu, alpha))."""
    _check(nu, 0.0)
    if not 0.0 < alpha < 1.0:
        raise ValueError(f'alpha must be in (0, 1), got {alpha}')
    lo, hi = 0.0, max(nu, 1.0)
    while sf(nu, hi) > alpha:       # sf falls from 1 to 0: bracket the root
        lo, hi = hi, 2.0 * hi
    x = 0.5 * (lo + hi)
    log_alpha = math.log(alpha)
    for _ in range(200):
        q = sf(nu, x)
        if q > alpha:
            lo = x
        else:
            hi = x
        # Newton on g(x) = log Q(x) - log alpha, g'(x) = -f(x) / Q(x), f the density
        log_f = (0.5 * nu - 1.0) * math.log(x) - 0.5 * x - 0.5 * nu * math.log(2.0) \
            - math.lgamma(0.5 * nu)
        step = (math.log(q) - log_alpha) * q / math.exp(log_f) if q > 0.0 else math.inf
        new = x + step
        if not lo < new < hi:
            new = 0.5 * (lo + hi)
        if abs(new - x) <= XTOL * x or hi - lo <= XTOL * x:
            return new
        x = new
    return x
