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
Hostile sample streams for the sessions' property tests (Hypothesis).

Stamps in order, duplicated, late, ancient, far future, zero, negative, at and beyond the
largest a ROS stamp holds; values NaN, +-inf, 0, negative, denormal, +-1e308 and ordinary
ones.  Derandomized and small (CI has 2 cores): the same examples on every run.
"""

import math

from hypothesis import HealthCheck, settings, strategies as st
import numpy as np

from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import MAX_STAMP_NS, NS

T0 = 1_700_000_000 * NS
OWC = owc()
GOOD = float(OWC.C[0, 0] * 0.5435 + OWC.D[0])       # eq. (2) at the model's x0, mW
SETTINGS = settings(derandomize=True, max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])

values = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, 5e-324, -5e-324,
                     1e308, -1e308, 1e-300]),
    st.floats(min_value=GOOD - 300.0, max_value=GOOD + 300.0),
)
# how the next stamp relates to the newest one (ns)
moves = st.sampled_from(['next', 'next', 'next', 'half', 'gap', 'duplicate', 'late',
                         'ancient', 'future', 'zero', 'negative', 'max', 'beyond'])


def stamps_of(ops):
    """Turn the moves into stamps in ns, like a hostile publisher would send them."""
    newest, out = T0, []
    for move in ops:
        stamp = {
            'next': newest + NS, 'half': newest + NS // 2, 'gap': newest + 7 * NS,
            'duplicate': newest, 'late': newest - 3 * NS, 'ancient': newest - 10**4 * NS,
            'future': newest + 10**5 * NS, 'zero': 0, 'negative': -NS,
            'max': MAX_STAMP_NS, 'beyond': MAX_STAMP_NS + 1,
        }[move]
        if 0 < stamp <= MAX_STAMP_NS:
            newest = max(newest, stamp) if move != 'ancient' else newest
        out.append(stamp)
    return out


def check_psd(P, what):
    """Assert that P is finite, symmetric and positive semi-definite (relative tolerance)."""
    assert np.all(np.isfinite(P)), what
    assert np.allclose(P, P.T, rtol=0, atol=1e-9 * max(1.0, float(np.max(np.abs(P))))), what
    assert np.linalg.eigvalsh((P + P.T) / 2)[0] >= -1e-9 * max(1.0, float(np.trace(P))), what
