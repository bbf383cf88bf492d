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

"""Cases shared by the tests of tskf_ros.core.irregular: rotations and a PBH test on A^k."""

import numpy as np


def rotation(angle: float, scale: float = 1.0) -> np.ndarray:
    """Return scale * [[cos, -sin], [sin, cos]]: eigenvalues scale * exp(+-j angle)."""
    c, s = np.cos(angle), np.sin(angle)
    return scale * np.array([[c, -s], [s, c]])


ROT3 = rotation(2 * np.pi / 3, 1.1)


def pbh_detectable(Ak: np.ndarray, C: np.ndarray, tol: float = 1e-9) -> bool:
    """PBH on A^k itself: rank [A^k - lambda I; C] = n for every |lambda| >= 1."""
    n = Ak.shape[0]
    for lam in np.linalg.eigvals(Ak):
        if abs(lam) < 1 - 1e-9:
            continue
        M = np.vstack([Ak - lam * np.eye(n), C]) / max(1.0, abs(lam))
        if np.linalg.svd(M, compute_uv=False)[-1] <= tol:
            return False
    return True
