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

"""EstimatorConfig and model_from_flat: shapes from flat lists, and configs refused with why."""

import numpy as np
import pytest

from tskf_ros.core.linear_models import owc, spring_mass
from tskf_ros.owc.session import ConfigError, EstimatorConfig, model_from_flat


def test_model_from_flat_and_bad_configs():
    m = model_from_flat(A=[0, 1, -1, -2], C=[1, 0], G=[0, 1], Q=[1], R=[2], x0=[1, 1],
                        P0=[2, 0, 0, 3])
    np.testing.assert_array_equal(m.A, spring_mass().A)
    assert m.G.shape == (2, 1) and m.D is None
    with pytest.raises(ConfigError, match='A must have n'):
        model_from_flat(A=[1, 2], C=[1], Q=[1], R=[1], x0=[0], P0=[1])
    with pytest.raises(ConfigError, match='Q must have'):
        model_from_flat(A=[1], C=[1], Q=[1, 0], R=[1], x0=[0], P0=[1])
    with pytest.raises(ConfigError, match='indefinite'):
        EstimatorConfig(model_from_flat(A=[1], C=[1], Q=[-1], R=[1], x0=[0], P0=[1]))
    with pytest.raises(ConfigError, match='period'):
        EstimatorConfig(owc(), period=-1.0)
    with pytest.raises(ConfigError, match='transition'):
        EstimatorConfig(owc(), transition='rk4')
    with pytest.raises(ConfigError, match='measurement_range'):
        EstimatorConfig(owc(), measurement_range=(5.0, 1.0))


def test_config_is_validated_by_what_it_does():
    # before: accepted, then almost every sample was refused
    with pytest.raises(ConfigError, match='a step of mu = (period = )?1 s from x0, P0'):
        EstimatorConfig(model_from_flat(A=[1.0], C=[-637.35], D=[511.97], Q=[1e308],
                                        R=[100.0], x0=[0.5], P0=[0.01]))
    with pytest.raises(ConfigError, match='initial state is absurd'):
        EstimatorConfig(model_from_flat(A=[1.0], C=[-637.35], D=[511.97], Q=[1.0],
                                        R=[100.0], x0=[1e308], P0=[0.01]))
