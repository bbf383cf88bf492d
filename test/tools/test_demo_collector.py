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

"""The demo's collecting client: the in-process pipeline equals the core filter offline."""

import numpy as np

from tskf_ros.core.linear_models import owc, run_filter
from tskf_ros.core.time_scales import discrete
from tskf_ros.core.units import NS
from tskf_ros.experiments.demo_summary import summarise
from tskf_ros.tools.demo_collector import arrays, run_in_process

# s: a bound on waiting for DDS, never an assertion about timing
TIMEOUT = 60.0


def test_demo_pipeline_in_process():
    # one process, one executor: the best-effort power reaches the estimator and the
    # collector within the publish call, into queues (100 and 10 000) deeper than the 60
    # samples, so the exact counts below are not at the mercy of the transport
    record = run_in_process(duration=60.0, time_factor=200.0, seed=0, timeout=TIMEOUT)
    s = summarise(record)
    assert s.samples == 60 and s.predicted == s.published and s.corrected == s.published - 1
    # the estimates are the core filter run offline on the received time scale
    t, y = arrays(record.power)
    ref = run_filter(owc(), discrete(t / NS), y[:, None])
    tp, xp = arrays(record.predicted)
    np.testing.assert_array_equal(tp, t)
    np.testing.assert_allclose(xp, ref.x_pred[:, 0], rtol=0, atol=1e-9)
    assert np.isfinite(s.rms_corrected) and s.rms_corrected < s.rms_predicted
