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
Finding the light during the search scan, and the EKF's start from what the scan saw.

Not in Solanki et al. (2018).  Detection is Page's CUSUM on the intensity,
S_k = max(0, S_{k-1} + z_k - k_ref), light when S_k > h (Page 1954; its false-alarm
rate in the dark from Siegmund's approximation, doc/pointing.md).  The hand-over fits
z_i = x1 g(b_i - c) + v_i (eq. (4), (8)) to the last `window` samples at base angles
b_i by least squares over a grid of bearings c (x1 in closed form for each c), and sets
the covariance of [x1, c] to sigma^2 (J^T J)^{-1} with J = [g, -x1 g'] (Fisher).
"""

from dataclasses import dataclass
import math
from typing import NamedTuple, Optional

import numpy as np

from tskf_ros.led.acquisition_scan import Mask
from tskf_ros.led.intensity_model import AlignmentError, FloatArray, IncidenceResponse


@dataclass(frozen=True)
class DetectorConfig:
    """CUSUM reference and threshold (V), samples kept for the fit, the fit's grid."""

    reference: float = 1.0       # V: k_ref, about half the intensity in the beam
    threshold: float = 4.0       # V: h; with noise 1 V, one false detection in ~1.5e4 samples
    window: int = 12             # samples (base angle, intensity) the hand-over fits
    grid_step: float = 0.5       # deg between the bearings the fit tries
    margin: float = 6.0          # deg: the bearings tried reach this far beyond the samples

    def __post_init__(self) -> None:
        """Check the detector; raise AlignmentError with the reason."""
        for name in ('reference', 'threshold', 'grid_step', 'margin'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise AlignmentError(f'detector {name} must be positive, got {value}')
        if self.window < 3:
            raise AlignmentError(f'the detector window needs at least 3 samples, '
                                 f'got {self.window}')


def page_cusum(S: FloatArray, z: FloatArray, reference: FloatArray, have: Mask) -> FloatArray:
    """Return Page's CUSUM S_k = max(0, S_{k-1} + z_k - k_ref) where `have`, else S_{k-1}."""
    return np.where(have, np.maximum(0.0, S + np.where(have, z, 0.0) - reference), S)


class Sighting(NamedTuple):
    """What the scan saw, per found run: peak factor x1 (V), bearing c (deg), cov of [x1, c]."""

    x1: FloatArray
    bearing: FloatArray
    P: FloatArray


class LightDetector:
    """CUSUM detection and the least-squares bearing fit, for every run."""

    def __init__(self, config: DetectorConfig, response: IncidenceResponse, runs: int) -> None:
        self.config = config
        self.response = response
        self.runs = int(runs)
        self.cusum = np.zeros(self.runs)
        self.base = np.full((self.runs, config.window), np.nan)
        self.z = np.full((self.runs, config.window), np.nan)
        self.head = 0

    def reset(self, mask: Mask) -> None:
        """Forget the runs in mask (a new search begins)."""
        self.cusum[mask] = 0.0
        self.base[mask] = np.nan
        self.z[mask] = np.nan

    def update(self, z: FloatArray, base: FloatArray, mask: Mask,
               scale: Optional[FloatArray] = None) -> Mask:
        """
        Take z (NaN: missing) seen at base angles `base`; return the runs that see light.

        scale (per run, in (0, 1]; None: 1) multiplies k_ref and divides h, for a light
        known to be dimmer: k_ref h, and with it the false-alarm rate, stays about the same.
        """
        c = self.config
        have = mask & np.isfinite(z)
        scale = np.ones(self.runs) if scale is None else np.clip(scale, 1e-3, 1.0)
        self.cusum = page_cusum(self.cusum, z, c.reference * scale, have)
        self.base[:, self.head] = np.where(have, base, np.nan)
        self.z[:, self.head] = np.where(have, z, np.nan)
        self.head = (self.head + 1) % c.window
        return have & (self.cusum > c.threshold / scale)

    def sighting(self, mask: Mask, noise: float) -> Sighting:
        """Fit x1 g(b - c) to the kept samples of the runs in mask; noise: sigma of v (V)."""
        c, g = self.config, self.response
        b, z = self.base[mask], self.z[mask]                      # (m, window)
        ok = np.isfinite(z)
        b0 = np.where(ok, b, 0.0)
        z0 = np.where(ok, z, 0.0)
        lo = np.min(np.where(ok, b, np.inf), axis=1) - c.margin
        hi = np.max(np.where(ok, b, -np.inf), axis=1) + c.margin
        n_grid = int(math.ceil(float(np.max(hi - lo)) / c.grid_step)) + 1
        offsets = np.arange(n_grid) * c.grid_step
        bearings = lo[:, None] + offsets[None, :]                  # (m, grid)
        phi = b0[:, None, :] - bearings[:, :, None]                # (m, grid, window)
        gv = np.where(ok[:, None, :], g.g(phi), 0.0)
        zg = np.einsum('mgw,mw->mg', gv, z0)
        gg = np.einsum('mgw,mgw->mg', gv, gv)
        with np.errstate(divide='ignore', invalid='ignore'):
            # for each bearing: x1 = sum z g / sum g^2, and the squared residual drops by
            # (sum z g)^2 / sum g^2 (only positive x1: the light is not negative)
            score = np.where((zg > 0) & (gg > 0) & (bearings <= hi[:, None]), zg * zg / gg,
                             -np.inf)
        best = np.argmax(score, axis=1)
        rows = np.arange(best.size)
        bearing = bearings[rows, best]
        x1 = np.where(gg[rows, best] > 0, zg[rows, best] / np.maximum(gg[rows, best], 1e-300),
                      0.0)
        x1 = np.maximum(x1, 0.0)
        phi_best = np.where(ok, b0 - bearing[:, None], 0.0)
        # J rows: d/dx1 = g(b - c), d/dc = -x1 g'(b - c)
        g_best, dg_best = g.g_dg(phi_best)
        J = np.stack([np.where(ok, g_best, 0.0),
                      np.where(ok, -x1[:, None] * dg_best, 0.0)], axis=-1)
        info = np.einsum('mwi,mwj->mij', J, J) / max(noise, 1e-6) ** 2
        info += np.eye(2) * 1e-9
        P = np.linalg.inv(info)
        return Sighting(x1, bearing, P)
