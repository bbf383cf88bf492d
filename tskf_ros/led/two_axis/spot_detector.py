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
Finding the light during the spiral search, and the conical-scan EKF's start from it.

The two-axis form of light_detector: detection is the same Page CUSUM on the intensity
(light_detector.page_cusum); the hand-over fits z_i = x1 g_r(|p_i - c|) + v_i to the
last `window` samples at boresight positions p_i (the exact offsets of their joints from
the newest sample's, pointing_geometry.log_offset) by least squares over a
grid of source positions c (x1 in closed form for each c: x1 = sum z g / sum g^2, and
the squared residual drops by (sum z g)^2 / sum g^2), a coarse grid over the samples'
bounding box and a fine one around its best point; the covariance of [x1, c_1, c_2] is
sigma^2 (J^T J)^{-1} with J = [g_r, -x1 grad g_r(p - c)] (Fisher).  The window is longer
than one arm of the spiral crossing the light, so that it holds samples of the inner arm
too: one arm alone leaves c's mirror image across the arm about as likely.
"""

from dataclasses import dataclass
import math
from typing import NamedTuple, Optional

import numpy as np

from tskf_ros.led.acquisition_scan import Mask
from tskf_ros.led.intensity_model import AlignmentError, FloatArray
from tskf_ros.led.light_detector import page_cusum
from tskf_ros.led.two_axis.pointing_geometry import displaced, log_offset
from tskf_ros.led.two_axis.radial_response import RadialResponse


@dataclass(frozen=True)
class SpotConfig:
    """CUSUM reference and threshold (V), samples kept for the fit, the fit's grids."""

    # V: k_ref, half the light a crossing sees (Page's k for a shift from 0 to 2 k_ref):
    # 1.6 V is a light 6 deg off an arm of the spiral (70 % of its peak) that the link's
    # x1 walk has dimmed to 2.3 V; at 1 V, 1.0 V missed 53 runs of 7000 within 10 s, 0.8 V 30
    reference: float = 0.8
    # V: h; below light_detector's 4 V: a spiral crosses the light in a few samples (the
    # dark's false alarms cost a hand-over and a loss, a missed crossing a whole spiral)
    threshold: float = 3.0
    # h in standard deviations of the noise the detector is told (SpotDetector's noise):
    # h = min(threshold, threshold_sigmas sigma).  The run length of Page's CUSUM in the
    # dark is a function of h / sigma and k_ref / sigma (Page 1954), so at a noise below
    # 1 V (k_ref >= sigma) h = 3 sigma keeps the dark's false alarms at or below those of
    # 3 V at 1 V; a fixed 3 V at 0 V needs the light above k_ref for longer than a
    # crossing of an arm lasts (at 0 V the CUSUM peaked at 2.3 to 2.9 V over crossings)
    threshold_sigmas: float = 3.0
    window: int = 40             # samples (position, intensity) the hand-over fits
    coarse: float = 1.5          # deg between the source positions of the coarse grid
    fine: float = 0.25           # deg: the fine grid around the coarse grid's best
    margin: float = 8.0          # deg: the coarse grid reaches this far beyond the samples
    span: float = 40.0           # deg: and at most this far around the newest sample
    # V: the fit's x1 g_r(0) is at most this (1.5 times the 3 V peak of Section V): a
    # crossing seen from one side cannot tell a bright light far off from a dim one near
    max_peak: float = 4.5

    def __post_init__(self) -> None:
        """Check the detector; raise AlignmentError with the reason."""
        for name in ('reference', 'threshold', 'threshold_sigmas', 'coarse', 'fine', 'margin',
                     'span', 'max_peak'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise AlignmentError(f'detector {name} must be positive, got {value}')
        if self.window < 4:
            raise AlignmentError(f'the detector window needs at least 4 samples, '
                                 f'got {self.window}')


class SpotSighting(NamedTuple):
    """What the spiral saw, per found run: x1 (V), the source's joints (m, 2), cov of [x1, c]."""

    x1: FloatArray
    center: FloatArray
    P: FloatArray


class SpotDetector:
    """CUSUM detection and the least-squares fit of the source position, for every run."""

    def __init__(self, config: SpotConfig, response: RadialResponse, runs: int,
                 noise: Optional[float] = None) -> None:
        """Keep `runs` CUSUMs; noise: sigma of v (V) for h (None: h = config.threshold)."""
        self.config = config
        # h (V): min(threshold, threshold_sigmas sigma) for a known sigma
        self.threshold = (config.threshold if noise is None
                          else min(config.threshold, config.threshold_sigmas * float(noise)))
        self.response = response
        self.runs = int(runs)
        self.cusum = np.zeros(self.runs)
        self.position = np.full((self.runs, config.window, 2), np.nan)
        self.z = np.full((self.runs, config.window), np.nan)
        self.head = 0

    def reset(self, mask: Mask) -> None:
        """Forget the runs in mask (a new search begins)."""
        self.cusum[mask] = 0.0
        self.position[mask] = np.nan
        self.z[mask] = np.nan

    def update(self, z: FloatArray, position: FloatArray, mask: Mask,
               scale: Optional[FloatArray] = None) -> Mask:
        """
        Take z (NaN: missing) seen at positions (runs, 2); return the runs that see light.

        scale (per run, in (0, 1]; None: 1) multiplies k_ref and divides h, for a light
        known to be dimmer, as light_detector's.
        """
        c = self.config
        have = mask & np.isfinite(z)
        scale = np.ones(self.runs) if scale is None else np.clip(scale, 1e-3, 1.0)
        self.cusum = page_cusum(self.cusum, z, c.reference * scale, have)
        self.position[:, self.head] = np.where(have[:, None], position, np.nan)
        self.z[:, self.head] = np.where(have, z, np.nan)
        newest = self.head
        self.head = (self.head + 1) % c.window
        self._newest = newest
        return have & (self.cusum > self.threshold / scale)

    def _best(self, p: FloatArray, z: FloatArray, ok: Mask,
              centers: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return the score and x1 of each candidate centre (m, G, 2) for samples (m, W)."""
        e = p[:, None, :, :] - centers[:, :, None, :]                    # (m, G, W, 2)
        gv = np.where(ok[:, None, :], self.response.g(np.hypot(e[..., 0], e[..., 1])), 0.0)
        zg = np.einsum('mgw,mw->mg', gv, np.where(ok, z, 0.0))
        gg = np.einsum('mgw,mgw->mg', gv, gv)
        # x1 = sum z g / sum g^2 within [0, max_peak / g_r(0)]; the squared residual drops
        # by 2 x1 sum z g - x1^2 sum g^2 ((sum z g)^2 / sum g^2 where x1 is not clipped)
        x1 = np.clip(zg / np.maximum(gg, 1e-300), 0.0, self.config.max_peak / self.response.peak)
        score = np.where((zg > 0) & (gg > 0), 2.0 * x1 * zg - x1 * x1 * gg, -np.inf)
        return score, x1

    def sighting(self, mask: Mask, noise: float) -> SpotSighting:
        """Fit x1 g_r(|p - c|) to the kept samples of the runs in mask; noise: sigma of v."""
        c = self.config
        joints, z = self.position[mask], self.z[mask]                     # (m, W, 2), (m, W)
        ok = np.isfinite(z)
        # the origin is the newest kept sample's position: the newest slot is empty when
        # that sample was missing (a dropout); a run with none kept (the detector fires on a
        # kept sample, so none here) would be fit around [0, 0]
        age = (self._newest - np.arange(c.window)) % c.window              # 0: the newest
        kept = np.argmin(np.where(ok, age[None, :], c.window), axis=1)
        origin = joints[np.arange(joints.shape[0]), kept]                 # (m, 2)
        origin = np.where(np.isfinite(origin), origin, 0.0)
        p = log_offset(origin[:, None, 0], origin[:, None, 1], np.where(ok, joints[..., 0], 0.0),
                       np.where(ok, joints[..., 1], 0.0))
        p0 = np.where(ok[..., None], p, 0.0)
        newest = np.zeros_like(origin)
        lo = np.maximum(np.min(np.where(ok[..., None], p, np.inf), axis=1) - c.margin,
                        newest - c.span)
        hi = np.minimum(np.max(np.where(ok[..., None], p, -np.inf), axis=1) + c.margin,
                        newest + c.span)
        n = int(math.ceil(float(np.max(hi - lo)) / c.coarse)) + 1
        steps = np.arange(n) * c.coarse
        gx, gy = np.meshgrid(steps, steps, indexing='ij')
        grid = np.stack([gx.ravel(), gy.ravel()], axis=-1)                # (G, 2)
        centers = lo[:, None, :] + grid[None, :, :]
        inside = np.all(centers <= hi[:, None, :], axis=-1)
        score, _ = self._best(p0, z, ok, centers)
        best = centers[np.arange(centers.shape[0]), np.argmax(np.where(inside, score,
                                                                       -np.inf), axis=1)]
        k = int(math.ceil(c.coarse / c.fine))
        local = np.arange(-k, k + 1) * c.fine
        fx, fy = np.meshgrid(local, local, indexing='ij')
        fine = best[:, None, :] + np.stack([fx.ravel(), fy.ravel()], axis=-1)[None]
        score, x1s = self._best(p0, z, ok, fine)
        i = np.argmax(score, axis=1)
        rows = np.arange(fine.shape[0])
        center, x1 = fine[rows, i], np.maximum(x1s[rows, i], 0.0)
        e = p0 - center[:, None, :]
        g = np.where(ok, self.response.g(np.hypot(e[..., 0], e[..., 1])), 0.0)
        grad = np.where(ok[..., None], self.response.gradient(e), 0.0)
        # J rows: d/dx1 = g_r(|p - c|), d/dc = -x1 grad g_r(p - c)
        J = np.concatenate([g[..., None], -x1[:, None, None] * grad], axis=-1)
        info = np.einsum('mwi,mwj->mij', J, J) / max(noise, 1e-6) ** 2 + np.eye(3) * 1e-9
        return SpotSighting(x1, displaced(origin[:, 0], origin[:, 1], center),
                            np.linalg.inv(info))
