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
Property-based tests (Hypothesis) of the alignment session under hostile input.

For arbitrary sequences of stamps and values (test/hostile_streams.py):

- nothing raises;
- nothing non-finite, and nothing beyond the configured limits, is returned for
  publishing (state, covariance, commands, stamps);
- every returned covariance is symmetric positive semi-definite;
- after the hostile sequence, ordinary samples are used again within a bounded number.

The estimator session's own: test/owc/session/.
"""

import math

from hostile_streams import check_psd, moves, SETTINGS, stamps_of, T0, values
from hypothesis import given, strategies as st
import numpy as np

from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.led.alignment_session import AlignmentConfig, AlignmentSession


@SETTINGS
@given(st.lists(st.tuples(moves, values), min_size=1, max_size=40),
       st.sampled_from(['ekf', 'hill_climbing', 'three_point']))
def test_alignment_session_survives_anything_and_recovers(ops, algorithm):
    config = AlignmentConfig(algorithm=algorithm)
    lo, hi = config.base_limits
    session = AlignmentSession(config)
    intensities = [v / 100.0 if math.isfinite(v) and abs(v) < 1e5 else v for _, v in ops]
    for stamp, z in zip(stamps_of([m for m, _ in ops]), intensities):
        out = session.add(stamp, z, now_ns=T0)
        if out.command is not None:
            assert math.isfinite(out.command) and lo <= out.command <= hi
            assert abs(out.turn) <= config.max_step + 1e-9
        for est in (out.prior, out.posterior):
            if est is not None:
                assert np.all(np.isfinite(est[0]))
                assert float(np.max(np.abs(est[0]))) <= config.state_limit
                check_psd(est[1], out.stamp_ns)
    session.diagnostics(now_ns=T0)
    start = MAX_STAMP_NS - 100 * NS
    outs = [session.add(start + k * NS // 20, 2.0, now_ns=T0) for k in range(10)]
    assert all(o.status == 'used' and o.command is not None for o in outs[-5:]), [
        (o.status, o.reason) for o in outs]
