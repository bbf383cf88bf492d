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

"""The estimate encoder's inputs: the filter's arrays as they are, anything else converted."""

import numpy as np
import pytest

from tskf_ros.messages.estimate_cdr import EstimateEncoder

NAMES = ('theta', 'omega')


def test_other_array_types_give_the_bytes_of_their_float64_values():
    enc = EstimateEncoder(NAMES)
    t, mu = 1_700_000_000_123_456_789, 1e-3
    x, P = np.array([0.5, -1.25]), np.array([[4.0, 0.3], [0.3, 0.25]])
    assert enc.estimate('predicted', t, mu, x.tolist(), P.tolist()) == \
        enc.estimate('predicted', t, mu, x, P)
    for x_, P_ in ((x.astype(np.float32), P.astype(np.float32)), (x[None], P.reshape(-1)),
                   (x[::-1][::-1], np.asfortranarray(P)), (x.astype('>f8'), P.T.T),
                   (x.astype(np.int64), P.astype(np.int64))):
        x64 = np.array(x_, dtype=float).reshape(2)
        P64 = np.array(P_, dtype=float).reshape(2, 2)
        assert enc.estimate('predicted', t, mu, x_, P_) == \
            enc.estimate('predicted', t, mu, x64, P64)


@pytest.mark.parametrize('x, P', [
    (np.zeros(3), np.zeros(3)),          # n + n * n values in all, the wrong split
    (np.zeros(1), np.zeros((2, 2))),
    (np.zeros(2), np.zeros((3, 3))),
])
def test_a_state_of_another_size_is_refused(x, P):
    with pytest.raises(ValueError):
        EstimateEncoder(NAMES).estimate('corrected', 1, 1e-3, x, P)
