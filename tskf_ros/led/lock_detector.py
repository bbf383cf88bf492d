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
Loss-of-lock detection for the LED aligner: windowed NIS and M-of-N low intensity, per run.

Not in Solanki et al. (2018).  The normalized innovation squared of each used sample,
e_k = nu_k^2 / S_k (row 1 of eq. (12) against the prior of eq. (13)-(14)), is chi^2(1)
when the EKF is consistent; a gate at g standard deviations keeps only e < g^2, so the
kept e are a truncated chi^2(1) with (for chi^2(k) truncated at G = g^2, F_k its cdf)

    m = k F_{k+2}(G) / F_k(G),     E[e^2] = k (k + 2) F_{k+4}(G) / F_k(G).

The sum of n kept e is taken as a chi^2(nu) scaled by a (a = var / 2m, nu = 2 n m^2 /
var: Welch-Satterthwaite), and its upper alpha quantile is the band.  Lost when M of the
last N intensities are below `level`, or when the windowed NIS is above its band and at
least `corroborate` of the N are low.  The thresholds: doc/pointing.md.
"""

from dataclasses import dataclass
import math
from typing import NamedTuple, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.core import chi_square
from tskf_ros.led.acquisition_scan import Mask
from tskf_ros.led.intensity_model import AlignmentError, FloatArray


class TruncatedMoments(NamedTuple):
    """Mean and variance of one chi^2(1) NIS kept by a gate (inf: no gate)."""

    mean: float
    var: float


def truncated_chi2_moments(gate: float, dof: int = 1) -> TruncatedMoments:
    """Return the mean and variance of chi^2(dof) given that it is below gate^2."""
    if not gate > 0.0 or math.isinf(gate):
        return TruncatedMoments(float(dof), 2.0 * dof)
    G = gate * gate
    # the chi^2(k) CDF at G (scipy.special.chdtr(k, G), equal to 1e-12: the test)
    F = chi_square.cdf
    p = F(dof, G)
    mean = dof * F(dof + 2, G) / p
    second = dof * (dof + 2) * F(dof + 4, G) / p
    return TruncatedMoments(float(mean), float(second - mean * mean))


def nis_band(n: int, alpha: float, gate: float = 0.0) -> float:
    """Return the upper alpha quantile of the sum of n gated chi^2(1) NIS (0 for n = 0)."""
    if n <= 0:
        return 0.0
    m, v = truncated_chi2_moments(gate)
    a, nu = v / (2.0 * m), 2.0 * n * m * m / v
    # chi2.isf(alpha, nu) (scipy.special.chdtri(nu, alpha), equal to 1e-12: the test)
    return float(a * chi_square.isf(alpha, nu))


@dataclass(frozen=True)
class LockConfig:
    """The loss-of-lock tests: window N, M of N below level, the NIS band's alpha and gate."""

    window: int = 20              # N samples in both windows (1 s at 50 ms)
    low_count: int = 12           # M: lost when M of the last N intensities are below level
    level: float = 0.6            # V: 20% of the 3 V peak, the edge of the tracking zone
    nis_alpha: float = 1e-4       # probability that a consistent EKF's window exceeds the band
    gate: float = 0.0             # the innovation gate (std devs) the NIS went through; 0 off
    corroborate: int = 8          # low samples of N that confirm a NIS above its band

    def __post_init__(self) -> None:
        """Check the tests; raise AlignmentError with the reason."""
        if self.window < 2:
            raise AlignmentError(f'lock window must be at least 2 samples, got {self.window}')
        if not 1 <= self.low_count <= self.window:
            raise AlignmentError(f'low_count must be in [1, window = {self.window}], '
                                 f'got {self.low_count}')
        if not 0 <= self.corroborate <= self.low_count:
            raise AlignmentError(f'corroborate must be in [0, low_count = {self.low_count}], '
                                 f'got {self.corroborate}')
        if not math.isfinite(self.level):
            raise AlignmentError(f'level must be finite, got {self.level}')
        if not 0.0 < self.nis_alpha < 1.0:
            raise AlignmentError(f'nis_alpha must be in (0, 1), got {self.nis_alpha}')
        if not (math.isfinite(self.gate) and self.gate >= 0.0):
            raise AlignmentError(f'gate must be >= 0, got {self.gate}')


class LockVerdict(NamedTuple):
    """Per run: lost, the low-intensity count, the windowed NIS and its band (NaN: none)."""

    lost: Mask
    low: FloatArray
    nis: FloatArray
    band: FloatArray


class LockDetector:
    """The two windows of LockConfig for every run."""

    def __init__(self, config: LockConfig, runs: int) -> None:
        self.config = config
        self.runs = int(runs)
        n = config.window
        # the windows, one row per sample (the oldest is overwritten), one column per run:
        # low intensity, and the NIS values kept (0 where none)
        self.low = np.zeros((n, self.runs), dtype=bool)
        self.kept = np.zeros((n, self.runs), dtype=bool)
        self.nis = np.zeros((n, self.runs))
        self.head = 0
        # the band for every count of NIS values in the window
        self.bands = np.array([nis_band(k, config.nis_alpha, config.gate)
                               for k in range(n + 1)])

    def retune(self, config: LockConfig) -> None:
        """Take new thresholds (the same window size) in place: the windows are kept."""
        if config.window != self.config.window:
            raise AlignmentError('the lock window size changes only by a restart')
        if config.gate != self.config.gate or config.nis_alpha != self.config.nis_alpha:
            self.bands = np.array([nis_band(k, config.nis_alpha, config.gate)
                                   for k in range(config.window + 1)])
        self.config = config

    @property
    def counted(self) -> NDArray[np.int_]:
        """Per run: the NIS values in the window (the samples the filter took, gated)."""
        return self.kept.sum(axis=0)

    def reset(self, mask: Mask) -> None:
        """Empty the windows of the runs in mask (after a hand-over or a reset)."""
        self.low[:, mask] = False
        self.kept[:, mask] = False
        self.nis[:, mask] = 0.0

    def update(self, z: FloatArray, nis: FloatArray, mask: Mask,
               level: Optional[FloatArray] = None) -> LockVerdict:
        """
        Take z (NaN: missing) and its NIS (NaN: none) for the runs in mask; judge them.

        level: the low-intensity level per run (None: the configured one).
        """
        c = self.config
        level = np.full(self.runs, c.level) if level is None else level
        have = mask & np.isfinite(z)
        gate2 = c.gate * c.gate if c.gate > 0 else math.inf
        kept = have & np.isfinite(nis) & (nis < gate2)
        h = self.head
        self.low[h] = have & (z < level)
        self.kept[h] = kept
        self.nis[h] = np.where(kept, nis, 0.0)
        self.head = (h + 1) % c.window
        low = self.low.sum(axis=0)
        count = self.kept.sum(axis=0)
        total = self.nis.sum(axis=0)
        band = self.bands[count]
        # the NIS is judged once half the window has values
        high = (count >= (c.window + 1) // 2) & (total > band)
        lost = mask & ((low >= c.low_count) | (high & (low >= c.corroborate)))
        return LockVerdict(lost, low.astype(float), np.where(count > 0, total, np.nan),
                           np.where(count > 0, band, np.nan))
