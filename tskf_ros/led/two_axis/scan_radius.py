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
The conical scan's radius: what a sample tells about the pointing, and a dim-light radius.

A radius that widens when the light is dim is `ConicalEKFConfig.dim_radius` (6.5 deg by
default; 0 turns it off).

A sample taken at the scan offset s of a mean pointing error d is z = x1 g_r(|d + s|) + v,
v of variance R (conical_ekf).  Its Fisher information about x = [x1, d_c, d_e] is
grad h grad h^T / R with grad h = [g_r(rho), x1 g_r'(rho) (d + s) / rho], rho = |d + s|
(Kay, Fundamentals of Statistical Signal Processing: Estimation Theory, 1993, eq. (3.31)
for a Gaussian sample).  Averaged over the N points of one scan turn, s_j = r [cos phi_j,
sin phi_j], with the mean pointing on the source (d = 0, so rho = r), the cross terms
cancel (sum_j [cos phi_j, sin phi_j] = 0) and sum_j u_j u_j^T = N/2 I:

    J(r) = diag(g_r(r)^2, x1^2 g_r'(r)^2 / 2, x1^2 g_r'(r)^2 / 2) / R     per sample,

so each pointing axis gets x1^2 g_r'(r)^2 / (2 R) per sample, largest where |g_r'| is:
6.3 deg for the paper's g of eq. (4) in the tracking-zone unit, 1.36 times its value at
the default r = 4 deg (|g_r'(4)| is 86 % of its maximum).  Off the source (d != 0) and
with x1 unknown, the pointing's share is the Schur complement J_dd - J_d1 J_1d / J_11
(`pointing_information`), which the wider circle raises more: 1.5 times at |d| = 4 deg
and 1.7 times at 6 deg for r = 6.5 deg (doc/design/two_axis.md).  The price is the
scan's own loss, 1 - g_r(r)/g_r(0): 15 % at 4 deg, 34 % at 6.5 deg, and a boresight r off
the mean pointing.
"""

import numpy as np

from tskf_ros.led.intensity_model import FloatArray
from tskf_ros.led.two_axis.pointing_geometry import conical_scan
from tskf_ros.led.two_axis.radial_response import RadialResponse


def scan_information(radius: float, *, x1: float, R: float,
                     error: tuple[float, float] = (0.0, 0.0), points: int = 20,
                     response: RadialResponse = RadialResponse()) -> FloatArray:
    """
    Return the Fisher information of [x1, d_c, d_e] per sample, over one scan turn (3, 3).

    radius: r (deg); x1: the intensity factor (V); R: the sample's noise variance (V^2);
    error: the mean pointing error d (deg); points: samples per turn.
    """
    e = np.asarray(error, dtype=float) + conical_scan(radius, points)
    grad = np.empty((points, 3))
    grad[:, 0] = response.g(np.hypot(e[:, 0], e[:, 1]))
    grad[:, 1:] = x1 * response.gradient(e)
    return grad.T @ grad / (R * points)


def pointing_information(radius: float, *, x1: float, R: float,
                         error: tuple[float, float] = (0.0, 0.0), points: int = 20,
                         response: RadialResponse = RadialResponse()) -> float:
    """
    Return the information per sample and pointing axis with x1 unknown (deg^-2).

    Half the trace of the Schur complement J_dd - J_d1 J_1d / J_11 of `scan_information`
    (same arguments): the pointing's information once x1 is estimated as well.
    """
    J = scan_information(radius, x1=x1, R=R, error=error, points=points, response=response)
    schur = J[1:, 1:] - np.outer(J[1:, 0], J[0, 1:]) / J[0, 0]
    return float(np.trace(schur)) / 2.0


def dim_scan_radius(peak: FloatArray, radius: float, dim_radius: float,
                    dim_peak: float) -> FloatArray:
    """
    Return the scan radius per run for the estimated peak x1hat g_r(0) (V).

    A tent: radius at a peak of dim_peak or more, dim_radius at dim_peak / 2, radius again
    at dim_peak / 4 or less, linear in between (no switching back and forth at one level);
    radius everywhere if dim_radius is 0 (off).  Under dim_peak / 4 the light tells little
    about the pointing at any radius (the information goes as x1^2), and the wider circle
    would only put the boresight further from a mean pointing it cannot correct
    (doc/design/two_axis.md, "A scan that widens when the light is dim").
    """
    peak = np.asarray(peak, dtype=float)
    if dim_radius <= 0.0:
        return np.full(peak.shape, radius)
    up = np.clip((dim_peak - peak) / (0.5 * dim_peak), 0.0, 1.0)          # 0 -> 1 to dim_peak/2
    down = np.clip((0.5 * dim_peak - peak) / (0.25 * dim_peak), 0.0, 1.0)  # 0 -> 1 to dim_peak/4
    return radius + (dim_radius - radius) * (up - down)
