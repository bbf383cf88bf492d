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

"""The estimator session takes a message's variance as R, and refuses a wrong-size sample."""

import math

import numpy as np
import pytest

from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession

T0 = 1_700_000_000 * NS


def test_the_message_variance_is_the_measurement_noise_when_asked():
    # independent formulation: a textbook KF step with R_d = the message's variance
    model = owc()
    session = EstimatorSession(EstimatorConfig(model, use_message_variance=True, gate=0.0))
    session.add(T0, 300.0, 25.0)
    out = session.add(T0 + 2 * NS, 310.0, 25.0)       # mu = 2 s
    corrected = [e for e in out.estimates if e.kind == 'corrected'][0]
    x, P, C, D = model.x0, model.P0, model.C, model.D
    S = C @ P @ C.T + 25.0
    K = P @ C.T / S
    x_c = x + K @ (np.array([300.0]) - C @ x - D)
    P_c = (np.eye(1) - K @ C) @ P
    assert corrected.x == pytest.approx(x_c, rel=1e-9)
    assert corrected.P[0, 0] == pytest.approx(P_c[0, 0], rel=1e-9)
    plain = EstimatorSession(EstimatorConfig(model, gate=0.0))
    plain.add(T0, 300.0, 25.0)
    other = [e for e in plain.add(T0 + 2 * NS, 310.0, 25.0).estimates
             if e.kind == 'corrected'][0]
    assert not math.isclose(other.P[0, 0], corrected.P[0, 0], rel_tol=1e-3)  # R / mu used


def test_a_measurement_of_the_wrong_size_is_bad_size():
    session = EstimatorSession(EstimatorConfig(owc()))
    out = session.add(T0, [300.0, 301.0])
    assert (out.status, out.reason) == ('rejected', 'bad_size')
    assert session.diagnostics()[0].as_dict()['Rejected (bad_size)'] == '1'
