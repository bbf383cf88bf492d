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
The light-intensity model of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018), eq. (1)-(5).

    A = e^{-cd}                                            (1)
    E_theta(d) = I_theta e^{-cd} / d^2                     (2)
    P_in = E_theta(d) A_0 g(phi)                           (3)
    g(phi) = a1 e^{-((phi - b1)/c1)^2} + a2 e^{-((phi - b2)/c2)^2}     (4)
    V_d = C_p I_theta e^{-cd} g(phi) / d^2                 (5)

with the printed fit a1 = 0.6682, b1 = 7.752, c1 = 148.8, a2 = 0.3340, b2 = -13.57,
c2 = 325.8, evaluated at phi times `units_per_degree` (why: doc/design/alignment.md).
"""

from dataclasses import dataclass, field
import functools
import math
from typing import Optional, overload, Sequence, Union

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
# an angle or an array of angles: the functions of eq. (4) keep the kind they are given
Angles = Union[float, FloatArray]

# Eq. (4), the printed Gaussian fit of the photodiode's angular response (Fig. 5).
PAPER_G_COEFFICIENTS = (0.6682, 7.752, 148.8, 0.3340, -13.57, 325.8)
LITERAL_UNITS_PER_DEGREE = 1.0
TRACKING_ANGLE = 15.0           # degrees, Section V
TRACKING_LEVEL = 0.2            # fraction of the peak intensity, Section V
MAX_INTENSITY = 3.0             # volts, Section V


class AlignmentError(ValueError):
    """Bad configuration or bad call given to an aligner."""


@overload
def wrap_degrees(angle: float) -> float:
    ...


@overload
def wrap_degrees(angle: FloatArray) -> FloatArray:
    ...


def wrap_degrees(angle: Angles) -> Angles:
    """Wrap angles in degrees to [-180, 180): (angle + 180) mod 360 - 180."""
    a = np.asarray(angle, dtype=float) + 180.0
    if np.ndim(a) == 0:
        return a % 360.0 - 180.0
    # the remainder (slow) only where it changes something: a in [0, 360) is its own
    outside = ~((a >= 0.0) & (a < 360.0))
    if outside.any():
        a[outside] %= 360.0
    return a - 180.0


def attenuation(c: float, d: float) -> float:
    """Beer's law, eq. (1): A = e^{-cd}."""
    return math.exp(-c * d)


def irradiance(intensity: float, c: float, d: float) -> float:
    """Irradiance at the receiver, eq. (2): E_theta(d) = I_theta e^{-cd} / d^2."""
    return intensity * attenuation(c, d) / d ** 2


@overload
def _fit(u: float, coefficients: Sequence[float]) -> float:
    ...


@overload
def _fit(u: FloatArray, coefficients: Sequence[float]) -> FloatArray:
    ...


def _fit(u: Angles, coefficients: Sequence[float]) -> Angles:
    """Eq. (4) in fit units: a1 e^{-((u - b1)/c1)^2} + a2 e^{-((u - b2)/c2)^2}."""
    return _weighted(*_gaussians(u, coefficients), coefficients)


def _gaussians(u: Angles, coefficients: Sequence[float]) -> tuple[Angles, Angles]:
    """Return the two Gaussians of eq. (4) at u fit units: e^{-((u - b)/c)^2}."""
    _, b1, c1, _, b2, c2 = coefficients
    return np.exp(-((u - b1) / c1) ** 2), np.exp(-((u - b2) / c2) ** 2)


def _weighted(e1: Angles, e2: Angles, coefficients: Sequence[float]) -> Angles:
    """Eq. (4) from its Gaussians: a1 e1 + a2 e2."""
    return coefficients[0] * e1 + coefficients[3] * e2


def _slope(u: Angles, e1: Angles, e2: Angles, coefficients: Sequence[float],
           scale: float) -> Angles:
    """Return the derivative of eq. (4) in phi = u / scale, from its Gaussians at u."""
    a1, b1, c1, a2, b2, c2 = coefficients
    # d/du a e^{-((u - b)/c)^2} = -2 a (u - b) / c^2 e^{-((u - b)/c)^2}; du/dphi = scale
    return scale * (-2.0 * a1 * (u - b1) / c1 ** 2 * e1 - 2.0 * a2 * (u - b2) / c2 ** 2 * e2)


def _fit_peak(coefficients: Sequence[float]) -> tuple[float, float]:
    """Return (u, g(u)) at the maximum of eq. (4), in fit units."""
    return _fit_peak_of(tuple(coefficients))


def _bisect(f, lo: float, hi: float) -> float:
    """
    Return the root of f in [lo, hi] (f(lo), f(hi) of opposite signs) to the last float.

    Bisection until the bracket holds no float between its ends: no scipy to import at a
    node's start (scipy.optimize takes about 0.5 s), the same root as scipy's brentq to
    its tolerance (test/led/test_intensity_model.py).
    """
    f_lo = f(lo)
    while True:
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            return lo if abs(f_lo) <= abs(f(hi)) else hi
        f_mid = f(mid)
        if f_mid == 0.0:
            return mid
        if (f_mid < 0.0) == (f_lo < 0.0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid


@functools.lru_cache(maxsize=16)
def _fit_peak_of(coefficients: tuple[float, ...]) -> tuple[float, float]:
    """
    Return `_fit_peak` (cached: every IncidenceResponse needs it).

    The maximum between the two centres, where eq. (4)'s slope changes sign (each
    Gaussian rises towards its centre); an end of [b2, b1] if the slope keeps its sign.
    """
    b1, b2 = coefficients[1], coefficients[4]
    lo, hi = min(b1, b2), max(b1, b2)

    def slope(u: float) -> float:
        return float(_slope(u, *_gaussians(u, coefficients), coefficients, 1.0))

    if lo < hi and slope(lo) > 0.0 > slope(hi):
        u = _bisect(slope, lo, hi)
    else:
        u = max((lo, hi), key=lambda end: float(_fit(end, coefficients)))
    return float(u), float(_fit(u, coefficients))


@functools.lru_cache(maxsize=None)
def zone_units_per_degree(coefficients: tuple[float, ...] = PAPER_G_COEFFICIENTS, *,
                          angle: float = TRACKING_ANGLE, level: float = TRACKING_LEVEL) -> float:
    """
    Fit units per degree for which g(+-angle) averages `level` of g's peak.

    Solved by bisection on [1e-3, 1e3]; for the paper's fit, 15 degrees and 20% give 17.697.
    """
    _, peak = _fit_peak(coefficients)

    def excess(scale: float) -> float:
        mean = 0.5 * (_fit(angle * scale, coefficients) + _fit(-angle * scale, coefficients))
        return float(mean) / peak - level

    lo, hi = 1e-3, 1e3
    if (excess(lo) < 0.0) == (excess(hi) < 0.0):
        raise AlignmentError(f'g never averages {level:g} of its peak at +-{angle:g} degrees '
                             'for units per degree in [1e-3, 1e3]')
    return _bisect(excess, lo, hi)


@dataclass(frozen=True)
class IncidenceResponse:
    """
    g(phi) of eq. (4) with phi in degrees, evaluated at phi * units_per_degree.

    units_per_degree=None picks `zone_units_per_degree` (about 17.70, the default);
    pass LITERAL_UNITS_PER_DEGREE for the printed reading (phi in degrees).
    """

    coefficients: tuple[float, ...] = PAPER_G_COEFFICIENTS
    units_per_degree: Optional[float] = None
    peak_angle: float = field(init=False)
    peak: float = field(init=False)

    def __post_init__(self) -> None:
        if len(self.coefficients) != 6:
            raise AlignmentError('g needs six coefficients (a1, b1, c1, a2, b2, c2), '
                                 f'got {len(self.coefficients)}')
        scale = self.units_per_degree
        if scale is None:
            scale = zone_units_per_degree(tuple(self.coefficients))
        if not (math.isfinite(scale) and scale > 0.0):
            raise AlignmentError(f'units_per_degree must be positive, got {scale}')
        object.__setattr__(self, 'units_per_degree', float(scale))
        u_peak, peak = _fit_peak(self.coefficients)
        object.__setattr__(self, 'peak_angle', u_peak / scale)
        object.__setattr__(self, 'peak', peak)

    @overload
    def g(self, phi: float) -> float:
        ...

    @overload
    def g(self, phi: FloatArray) -> FloatArray:
        ...

    def g(self, phi: Angles) -> Angles:
        """Eq. (4) at phi degrees."""
        return _fit(np.asarray(phi, dtype=float) * self.units_per_degree, self.coefficients)

    @overload
    def dg(self, phi: float) -> float:
        ...

    @overload
    def dg(self, phi: FloatArray) -> FloatArray:
        ...

    def dg(self, phi: Angles) -> Angles:
        """g'(phi), the derivative of eq. (4) with respect to phi in degrees."""
        return self.g_dg(phi)[1]

    @overload
    def g_dg(self, phi: float) -> tuple[float, float]:
        ...

    @overload
    def g_dg(self, phi: FloatArray) -> tuple[FloatArray, FloatArray]:
        ...

    def g_dg(self, phi: Angles) -> tuple[Angles, Angles]:
        """Return g(phi) and g'(phi) (their exponentials evaluated once for both)."""
        s = self.units_per_degree
        assert s is not None                # set by __post_init__
        u = np.asarray(phi, dtype=float) * s
        e1, e2 = _gaussians(u, self.coefficients)
        return _weighted(e1, e2, self.coefficients), _slope(u, e1, e2, self.coefficients, s)
