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

"""The light-intensity model (Solanki et al. 2018, eq. (1)-(5)): g, g' and the unit of phi."""

import numpy as np
import pytest
from solanki_paper import dg_paper, g_paper

from tskf_ros import led


RESPONSE = led.IncidenceResponse()


def paper_peak():
    """Maximum of eq. (4) on a dense grid (1e-4 fit units), refined once."""
    u = np.arange(-20.0, 20.0, 1e-3)
    k = int(np.argmax(g_paper(u)))
    fine = np.arange(u[k] - 2e-3, u[k] + 2e-3, 1e-6)
    return float(np.max(g_paper(fine)))


def test_zone_unit_puts_20_percent_at_15_degrees():
    r = RESPONSE
    assert r.units_per_degree == pytest.approx(17.697, abs=5e-4)      # README: 17.697
    # independent: scan the unit s on a 1e-6 grid for where mean g(+-15 s) / peak = 0.2
    peak = paper_peak()
    assert r.peak == pytest.approx(peak, rel=1e-10)
    s = np.arange(17.69, 17.71, 1e-6)
    level = 0.5 * (g_paper(15.0 * s) + g_paper(-15.0 * s)) / peak
    k = int(np.flatnonzero(np.diff(np.sign(level - 0.2)))[0])
    assert s[k] <= r.units_per_degree + 1e-9 and r.units_per_degree <= s[k + 1] + 1e-9
    # and g in degrees is eq. (4) at phi * s
    phi = np.linspace(-40.0, 40.0, 17)
    np.testing.assert_allclose(r.g(phi), g_paper(phi * r.units_per_degree), rtol=1e-13)


@pytest.mark.parametrize('coefficients', [
    led.intensity_model.PAPER_G_COEFFICIENTS,
    (0.5, 3.0, 40.0, 0.5, -8.0, 90.0),
    (0.9, -2.0, 200.0, 0.1, 12.0, 60.0),
])
def test_peak_and_zone_unit_equal_scipys(coefficients):
    """The start-up's bisections give scipy.optimize's numbers (to 1e-12), without it."""
    import scipy.optimize
    from tskf_ros.led import intensity_model as im

    def slope(u):
        return im._slope(u, *im._gaussians(u, coefficients), coefficients, 1.0)

    b1, b2 = coefficients[1], coefficients[4]
    u_ref = scipy.optimize.brentq(slope, min(b1, b2), max(b1, b2), xtol=1e-14, rtol=1e-15)
    u, peak = im._fit_peak(coefficients)
    assert u == pytest.approx(u_ref, rel=1e-12, abs=1e-12)
    assert peak == pytest.approx(float(im._fit(u_ref, coefficients)), rel=1e-12)
    bounded = scipy.optimize.minimize_scalar(lambda x: -float(im._fit(x, coefficients)),
                                             bounds=(min(b1, b2), max(b1, b2)),
                                             method='bounded', options={'xatol': 1e-10})
    assert peak == pytest.approx(-bounded.fun, rel=1e-12)

    def excess(scale):
        mean = 0.5 * (im._fit(15.0 * scale, coefficients) + im._fit(-15.0 * scale, coefficients))
        return float(mean) / peak - 0.2

    scale_ref = scipy.optimize.brentq(excess, 1e-3, 1e3, xtol=1e-14, rtol=1e-15)
    assert im.zone_units_per_degree(tuple(coefficients)) == pytest.approx(scale_ref, rel=1e-12)


def test_zone_unit_without_a_crossing_is_one_clear_error():
    from tskf_ros.led import intensity_model as im
    with pytest.raises(led.AlignmentError, match='never averages'):
        im.zone_units_per_degree(im.PAPER_G_COEFFICIENTS, level=1.5)


def test_literal_unit_is_nearly_flat():
    r = led.IncidenceResponse(units_per_degree=led.LITERAL_UNITS_PER_DEGREE)
    peak = paper_peak()
    # README: above 98% of the peak over +-15 deg, still 39-41% of it at +-180 deg
    phi = np.linspace(-15.0, 15.0, 301)
    assert np.all(r.g(phi) / peak > 0.98) and np.all(g_paper(phi) / peak > 0.98)
    at_180 = r.g(np.array([-180.0, 180.0])) / peak
    assert np.all((at_180 >= 0.39) & (at_180 <= 0.41))
    np.testing.assert_allclose(at_180, g_paper([-180.0, 180.0]) / peak, rtol=1e-12)


def test_bad_unit_is_rejected():
    with pytest.raises(led.AlignmentError, match='units_per_degree'):
        led.IncidenceResponse(units_per_degree=0.0)


def test_dg_matches_the_hand_derivative_and_finite_differences():
    s = RESPONSE.units_per_degree
    phi = np.linspace(-40.0, 40.0, 81)
    np.testing.assert_allclose(RESPONSE.dg(phi), s * dg_paper(s * phi), rtol=1e-12, atol=1e-15)
    h = 1e-5
    numeric = (g_paper(s * (phi + h)) - g_paper(s * (phi - h))) / (2 * h)
    np.testing.assert_allclose(RESPONSE.dg(phi), numeric, rtol=1e-6, atol=1e-9)


def test_g_dg_is_g_and_dg():
    # one pair of exponentials for both: the same numbers as each alone, arrays and floats
    phi = np.linspace(-200.0, 200.0, 401)
    g, dg = RESPONSE.g_dg(phi)
    np.testing.assert_array_equal(g, RESPONSE.g(phi))
    np.testing.assert_array_equal(dg, RESPONSE.dg(phi))
    np.testing.assert_allclose(g, g_paper(RESPONSE.units_per_degree * phi), rtol=1e-15)
    assert RESPONSE.g_dg(3.5) == (RESPONSE.g(3.5), RESPONSE.dg(3.5))
