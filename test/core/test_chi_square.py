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

"""The chi-square cdf, survival function and upper quantile against scipy.special."""

import math

import numpy as np
import pytest
import scipy.special

from tskf_ros.core import chi_square

NU = [0.3, 0.5, 1.0, 1.7, 2.0, 3.0, 5.0, 7.3, 10.0, 20.0, 33.3, 60.0, 200.0]


@pytest.mark.parametrize('nu', NU)
def test_cdf_and_sf_equal_scipy(nu):
    for x in np.concatenate([np.geomspace(1e-6, 1.0, 30), np.linspace(1.0, 4 * nu + 80, 200)]):
        want_sf = scipy.special.chdtrc(nu, x)
        assert chi_square.cdf(nu, x) == pytest.approx(scipy.special.chdtr(nu, x),
                                                      rel=1e-12, abs=1e-15)
        # the survival function keeps its relative accuracy in the far tail
        assert chi_square.sf(nu, x) == pytest.approx(want_sf, rel=1e-11, abs=1e-300)


@pytest.mark.parametrize('nu', NU)
def test_upper_quantile_equals_chdtri(nu):
    for alpha in (1e-12, 1e-8, 1e-4, 1e-2, 0.1, 0.5, 0.9, 0.999):
        x = chi_square.isf(alpha, nu)
        assert x == pytest.approx(scipy.special.chdtri(nu, alpha), rel=1e-12)
        assert chi_square.sf(nu, x) == pytest.approx(alpha, rel=1e-10)


def test_edges():
    assert chi_square.cdf(3.0, 0.0) == 0.0 and chi_square.sf(3.0, -1.0) == 1.0
    assert chi_square.cdf(3.0, math.inf) == 1.0 and chi_square.sf(3.0, math.inf) == 0.0


@pytest.mark.parametrize('call', [lambda: chi_square.cdf(0.0, 1.0),
                                  lambda: chi_square.cdf(math.nan, 1.0),
                                  lambda: chi_square.sf(2.0, math.nan),
                                  lambda: chi_square.isf(0.0, 2.0),
                                  lambda: chi_square.isf(1.0, 2.0),
                                  lambda: chi_square.isf(0.5, -1.0)])
def test_bad_arguments_raise_one_clear_error(call):
    with pytest.raises(ValueError):
        call()
