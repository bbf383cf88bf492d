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

"""Eq. (4) of Solanki, Al-Rubaia & Tan 2018 written out from the paper, for the LED tests."""

import numpy as np

# Eq. (4) as printed in the paper (Section III): a1, b1, c1, a2, b2, c2
A1, B1, C1, A2, B2, C2 = 0.6682, 7.752, 148.8, 0.3340, -13.57, 325.8


def g_paper(u):
    """Eq. (4) in the fit's own unit, written here from the paper."""
    u = np.asarray(u, dtype=float)
    return A1 * np.exp(-((u - B1) / C1) ** 2) + A2 * np.exp(-((u - B2) / C2) ** 2)


def dg_paper(u):
    """d/du of eq. (4), differentiated by hand."""
    u = np.asarray(u, dtype=float)
    return (-2 * A1 * (u - B1) / C1 ** 2 * np.exp(-((u - B1) / C1) ** 2)
            - 2 * A2 * (u - B2) / C2 ** 2 * np.exp(-((u - B2) / C2) ** 2))
