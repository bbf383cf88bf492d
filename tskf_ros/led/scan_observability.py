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
The scanning EKF's observability (Solanki, Al-Rubaia & Tan, IEEE/ASME T-Mech 2018, Section IV).

det C_k != 0 keeps both states observable; the paper says G > 1/91 guarantees it for
2 degree scan steps (eq. (24)), but the inequality runs the other way (G <= 1/91
guarantees it; at G = 0.5 det C_k = 0 at x2hat^f = +-2 deg): `observability` reports
where it vanishes, `check_observability` warns with that list or refuses a gain.
"""

from dataclasses import dataclass
import functools
import math
from typing import Optional, Sequence
import warnings

import numpy as np

from tskf_ros.led.intensity_model import AlignmentError, IncidenceResponse

# Section IV, Fig. 7: the scan set Psi (degrees), visited cyclically.
SCAN_ANGLES = (-2.0, -4.0, -6.0, -8.0, -10.0, -8.0, -6.0, -4.0, -2.0, 0.0,
               2.0, 4.0, 6.0, 8.0, 10.0, 8.0, 6.0, 4.0, 2.0, 0.0)


class ObservabilityError(AlignmentError):
    """The P gain or the scan set cannot guarantee det C_k != 0 (Section IV)."""


# ---------------------------------------------------------------------------------------
# Observability (Section IV)


@dataclass(frozen=True)
class Observability:
    """
    Where the P controller (21) with gain G and the scan make det C_k vanish (Section IV).

    det C_k = 0 iff u_{k-1} + psi_k - psi_{k-1} = 0 (the two rows of (17) coincide), and
    with u_{k-1} = -G x2hat_{k-1}, x2hat^f_k = (1 - G) x2hat_{k-1} that is iff
    x2hat^f_k = (1 - G)/G (psi_k - psi_{k-1}) (eq. (24)).  `vanishing` lists those
    x2hat^f (deg) within |x2hat^f| < 180; none (guaranteed) when
    |(1 - G)/G| min|dpsi| >= 180, i.e. 0 < G <= 1/91 for 2 degree steps.  (The paper
    prints the opposite inequality, G > 1/91; doc/design/lqr.md, erratum.)  The "iff"
    needs g'/g strictly decreasing at both angles of (17); `monotone` is the interval of
    angles (deg) around the peak where it is (with the default fit unit about -10.2 to
    11.7 deg): beyond it det C_k can also vanish with the two angles apart, for any G.
    """

    gain: float
    max_gain: float                 # the largest G that guarantees det C_k != 0
    vanishing: tuple[float, ...]    # x2hat^f (deg) where det C_k = 0, |x2hat^f| < 180
    monotone: tuple[float, float] = (-180.0, 180.0)   # deg: where g'/g decreases

    @property
    def guaranteed(self) -> bool:
        """Tell whether det C_k != 0 at every |x2hat^f| < 180."""
        return not self.vanishing

    @property
    def message(self) -> str:
        """One line: what the gain guarantees, or where det C_k vanishes."""
        lo, hi = self.monotone
        where = (f'while both angles of (17) are within [{lo:.1f}, {hi:.1f}] deg, where '
                 "g'/g decreases")
        if self.guaranteed:
            return (f'P gain G = {self.gain:g} guarantees det C_k != 0 for |x2hat^f| < 180 '
                    f'deg (eq. (24), corrected) {where}')
        at = ', '.join(f'{v:+.4g}' for v in self.vanishing)
        return (f'P gain G = {self.gain:g} does not guarantee observability: det C_k = 0 '
                f'where the predicted scan mean x2hat^f is {at} deg (there the command '
                'cancels the scan step); only G <= '
                f'{self.max_gain:.6g} (= 1/{1.0 / self.max_gain:g}) guarantees det C_k != 0 '
                f'(eq. (24), corrected), and only {where}')


class ObservabilityWarning(UserWarning):
    """The P gain and scan leave states where det C_k = 0 (Section IV, eq. (24))."""


def max_gain(scan: Sequence[float] = SCAN_ANGLES, *, max_angle: float = 180.0) -> float:
    """
    Largest P gain with |(1 - G)/G| min|dpsi| >= max_angle: 1/91 for 2 degree steps.

    Eq. (24): det C_k = 0 needs x2hat^f = (1 - G)/G (psi_k - psi_{k-1}); with
    |x2hat^f| < 180 that cannot happen for any step of the scan when
    (1 - G)/G >= 180 / min|dpsi| (0 < G < 1).
    """
    steps = np.abs(np.diff(np.r_[scan, scan[0]]))
    if np.any(steps == 0.0):
        raise ObservabilityError('consecutive scan angles must differ, or the two rows of C_k '
                                 f'coincide (det C_k = 0): scan {tuple(scan)}')
    return 1.0 / (1.0 + max_angle / float(np.min(steps)))


def monotone_interval(response: Optional[IncidenceResponse] = None) -> tuple[float, float]:
    """Return the interval of angles (deg) around g's peak where g'/g strictly decreases."""
    response = response if response is not None else IncidenceResponse()
    return _monotone(tuple(response.coefficients), response.units_per_degree)


@functools.lru_cache(maxsize=16)
def _monotone(coefficients: tuple[float, ...], units_per_degree: Optional[float],
              step: float = 0.01) -> tuple[float, float]:
    response = IncidenceResponse(coefficients, units_per_degree)
    phi = np.arange(-180.0, 180.0 + step / 2, step)
    r = response.dg(phi) / response.g(phi)
    falling = np.diff(r) < 0.0
    peak = int(np.argmax(response.g(phi)))
    k = min(peak, falling.size - 1)
    lo = k
    while lo > 0 and falling[lo - 1]:
        lo -= 1
    hi = k
    while hi < falling.size - 1 and falling[hi + 1]:
        hi += 1
    return float(phi[lo]), float(phi[hi + 1])


def observability(gain: float, scan: Sequence[float] = SCAN_ANGLES,
                  response: Optional[IncidenceResponse] = None) -> Observability:
    """
    Return where det C_k vanishes for this gain and scan (eq. (24), corrected).

    Raise ObservabilityError for a gain the P controller cannot use (not 0 < G < 2:
    x2hat <- (1 - G) x2hat diverges or stands still) or a scan with a zero step.
    """
    if len(scan) < 2:
        raise ObservabilityError(f'the scan needs at least two angles, got {tuple(scan)}')
    g_max = max_gain(scan)
    if not (math.isfinite(gain) and 0.0 < gain < 2.0):
        raise ObservabilityError(f'P gain G = {gain:g} makes x2hat <- (1 - G) x2hat diverge '
                                 'or stand still; need 0 < G < 2')
    steps = np.unique(np.diff(np.r_[scan, scan[0]]))
    # (24): x2hat^f = (1 - G)/G (psi_k - psi_{k-1}), reachable while |x2hat^f| < 180
    # (the relative 1e-12 keeps G = 1/91 itself, where x2hat^f = +-180, on the safe side)
    x2f = (1.0 - gain) / gain * steps
    vanishing = tuple(sorted({float(v) for v in x2f if abs(v) < 180.0 * (1.0 - 1e-12)}))
    return Observability(gain=float(gain), max_gain=g_max, vanishing=vanishing,
                         monotone=monotone_interval(response))


def check_observability(gain: float, scan: Sequence[float] = SCAN_ANGLES,
                        response: Optional[IncidenceResponse] = None) -> Observability:
    """
    Check the gain and scan (eq. (24), corrected); return the report.

    Raise ObservabilityError where the P controller cannot work (see `observability`);
    warn (ObservabilityWarning) where det C_k can vanish, as at the paper's G = 0.5
    (x2hat^f = +-2 deg).
    """
    report = observability(gain, scan, response)
    if not report.guaranteed:
        warnings.warn(report.message, ObservabilityWarning, stacklevel=2)
    return report


# ---------------------------------------------------------------------------------------
# Aligners
