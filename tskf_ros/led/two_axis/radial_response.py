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
The photodiode's response to the off-axis angle theta, for a receiver pointed in two axes.

Solanki et al. (IEEE/ASME T-Mech 2018) fit g(phi) of eq. (4) to a signed angle in one plane;
its two Gaussians are centred a little off zero (b1 = 7.752, b2 = -13.57 fit units), so
g(+phi) != g(-phi).  Off axis in two dimensions only the angle theta >= 0 between the
boresight and the source is defined, and a response that depends on the direction around
the boresight as well would need a fit the paper does not give.  We take the mean of the
two sides,

    g_r(theta) = (g(theta) + g(-theta)) / 2
               = sum_i a_i e^{-(s^2 theta^2 + b_i^2) / c_i^2} cosh(kappa_i theta),
      kappa_i = 2 s b_i / c_i^2,   s = fit units per degree,

which is even and smooth in theta (so smooth in the two pointing errors at theta = 0), has
its maximum at theta = 0, and keeps the tracking zone of the one-axis model: the unit s
is chosen so that the mean of g(+-15 deg) is 20 % of g's peak
(`intensity_model.zone_units_per_degree`), which is g_r(15 deg) = 0.2002 g_r(0) (g's
peak is a little off 0).
"""

from dataclasses import dataclass, field

import numpy as np

from tskf_ros.led.intensity_model import FloatArray, IncidenceResponse, TRACKING_ANGLE


ANGLE_LIMIT = 1e4                        # deg: |theta| is taken as at most this


def _sinhc(x: FloatArray) -> FloatArray:
    """Return sinh(x) / x, 1 at x = 0 (a Taylor series below |x| = 1e-3)."""
    small = np.abs(x) < 1e-3
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 + x * x / 6.0, np.sinh(safe) / safe)


def _coshc3(x: FloatArray) -> FloatArray:
    """Return (x cosh(x) - sinh(x)) / x^3, 1/3 at x = 0 (a Taylor series below |x| = 1e-2)."""
    small = np.abs(x) < 1e-2
    safe = np.where(small, 1.0, x)
    return np.where(small, 1.0 / 3.0 + x * x / 30.0,
                    (safe * np.cosh(safe) - np.sinh(safe)) / safe ** 3)


@dataclass(frozen=True)
class RadialResponse:
    """g_r(theta) of the one-axis fit, theta in degrees; `peak` is g_r(0)."""

    response: IncidenceResponse = field(default_factory=IncidenceResponse)

    @property
    def peak(self) -> float:
        """Return g_r(0), the maximum."""
        return float(self.g(np.zeros(1))[0])

    def _terms(self, theta: FloatArray) -> tuple[FloatArray, ...]:
        """Per Gaussian i: (a_i e^{-(s^2 th^2 + b^2)/c^2}, s^2 / c^2, kappa_i), broadcast."""
        a1, b1, c1, a2, b2, c2 = self.response.coefficients
        s = float(self.response.units_per_degree or 1.0)
        a = np.array([a1, a2])
        b = np.array([b1, b2])
        c = np.array([c1, c2])
        # beyond +-1e4 deg every term is 0 in double precision (e^{-s^2 th^2/c^2} underflows
        # from about 3000 deg), but cosh(kappa th) overflows from about 5.7e4 deg, and 0 inf
        # would be NaN: an estimate carried far off (a long gap) reads no light, not NaN
        th = np.clip(np.asarray(theta, dtype=float), -ANGLE_LIMIT, ANGLE_LIMIT)[..., None]
        weight = a * np.exp(-(s * s * th * th + b * b) / (c * c))
        return weight, s * s / (c * c), 2.0 * s * b / (c * c), th

    def g(self, theta: FloatArray) -> FloatArray:
        """g_r(theta) = sum_i a_i e^{-(s^2 theta^2 + b_i^2)/c_i^2} cosh(kappa_i theta)."""
        weight, _, kappa, th = self._terms(theta)
        return np.sum(weight * np.cosh(kappa * th), axis=-1)

    def slope_over_theta(self, theta: FloatArray) -> FloatArray:
        """
        g_r'(theta) / theta, finite at theta = 0 (where it is g_r''(0)).

        d/dtheta of each term: a e^{..} (-2 s^2 theta / c^2 cosh(kappa theta)
        + kappa sinh(kappa theta)); divided by theta, sinh(kappa theta) / theta is
        kappa sinhc(kappa theta).
        """
        weight, s2c2, kappa, th = self._terms(theta)
        return np.sum(weight * (-2.0 * s2c2 * np.cosh(kappa * th)
                                + kappa * kappa * _sinhc(kappa * th)), axis=-1)

    def slope_over_theta_rate(self, theta: FloatArray) -> FloatArray:
        """
        (g_r'(theta) / theta)' / theta, finite at theta = 0 (where it is g_r''''(0) / 3).

        g_r'/theta = sum_i w_i f_i with w_i = a e^{..}, f_i = -2 s^2/c^2 cosh(kappa theta)
        + kappa^2 sinhc(kappa theta); w_i'/theta = -2 s^2/c^2 w_i and f_i'/theta =
        -2 s^2/c^2 kappa^2 sinhc(kappa theta) + kappa^4 coshc3(kappa theta), where
        coshc3(u) = (u cosh u - sinh u) / u^3.
        """
        weight, s2c2, kappa, th = self._terms(theta)
        u = kappa * th
        f = -2.0 * s2c2 * np.cosh(u) + kappa * kappa * _sinhc(u)
        f_rate = -2.0 * s2c2 * kappa * kappa * _sinhc(u) + kappa ** 4 * _coshc3(u)
        return np.sum(weight * (-2.0 * s2c2 * f + f_rate), axis=-1)

    def hessian(self, error: FloatArray) -> FloatArray:
        """
        Return d^2 g_r(|e|) / de de^T (..., 2, 2) for tangent-plane errors e (..., 2).

        The gradient is (g_r'/theta) e, so the Hessian is (g_r'/theta) I +
        ((g_r'/theta)'/theta) e e^T (`slope_over_theta`, `slope_over_theta_rate`).
        """
        error = np.asarray(error, dtype=float)
        theta = np.hypot(error[..., 0], error[..., 1])
        outer = error[..., :, None] * error[..., None, :]
        return (self.slope_over_theta(theta)[..., None, None] * np.eye(2)
                + self.slope_over_theta_rate(theta)[..., None, None] * outer)

    def gradient(self, error: FloatArray) -> FloatArray:
        """Return d g_r(|e|) / d e for tangent-plane errors e (..., 2): g_r'(theta)/theta e."""
        error = np.asarray(error, dtype=float)
        theta = np.hypot(error[..., 0], error[..., 1])
        return self.slope_over_theta(theta)[..., None] * error

    def zone_level(self, angle: float = TRACKING_ANGLE) -> float:
        """Return g_r(angle) / g_r(0): 0.2002 at 15 degrees in the tracking-zone unit."""
        return float(self.g(np.array([angle]))[0]) / self.peak
