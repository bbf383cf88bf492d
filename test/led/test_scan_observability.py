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

"""The scanning EKF's observability, Solanki et al. 2018 (Section IV, eq. (17), (21)-(24))."""

import warnings

import numpy as np
import pytest

from tskf_ros import led


def test_scan_set_is_the_papers():
    assert len(led.SCAN_ANGLES) == 20
    assert max(led.SCAN_ANGLES) == 10.0 and min(led.SCAN_ANGLES) == -10.0
    steps = np.abs(np.diff(np.r_[led.SCAN_ANGLES, led.SCAN_ANGLES[0]]))
    assert np.all(steps == 2.0)


def _det_after_command(gain, x2_prev, psi_prev, psi, x1=2.0):
    """Return det C_k of (17) written out: x2hat_{k-1} steered by (21), then predicted by (13)."""
    g = led.IncidenceResponse()
    u = -gain * x2_prev                      # (21)
    x2f = x2_prev + u                        # (13)
    a1, a2 = x2f + psi, x2f - u + psi_prev   # the arguments of the two rows of (17)
    C = np.array([[g.g(a1), x1 * g.dg(a1)], [g.g(a2), x1 * g.dg(a2)]])
    return float(np.linalg.det(C)), x2f


def test_observability_is_guaranteed_up_to_one_over_91():
    # erratum of (24): x2hat^f = (1 - G)/G dpsi with |dpsi| = 2 is out of |x2hat^f| < 180
    # for G <= 1/91, so det C_k != 0 there; the paper's printed "G > 1/91" runs the wrong way
    assert led.max_gain() == pytest.approx(1.0 / 91.0, rel=1e-15)
    eps = 1e-6
    for gain in (1.0 / 91.0, 1.0 / 91.0 - eps, 0.005):
        report = led.observability(gain)
        assert report.guaranteed and report.vanishing == ()
        with warnings.catch_warnings():
            warnings.simplefilter('error')
            led.check_observability(gain)
        led.ScanningEKF(led.EKFConfig(gain=gain))
        # det C_k written out keeps its sign (never 0) while both angles of (17) stay where
        # g'/g decreases, for both step signs
        lo, hi = report.monotone
        for dpsi in (2.0, -2.0):
            # a1 = x2hat^f + dpsi, a2 = x2hat_{k-1} = x2hat^f / (1 - G): both in [lo, hi]
            x2f = np.linspace(lo + 2.5, hi - 2.5, 2001)
            det = np.array([_det_after_command(gain, x / (1 - gain), 0.0, dpsi)[0]
                            for x in x2f])
            assert np.all(det > 0.0) or np.all(det < 0.0)
    report = led.observability(1.0 / 91.0 + eps)
    assert not report.guaranteed
    # x2hat^f = (1 - G)/G * 2 = 90 * 2 / (1 + 91 eps) + O(eps^2): just inside 180
    want = (1 - (1 / 91 + eps)) / (1 / 91 + eps) * 2.0
    np.testing.assert_allclose(report.vanishing, [-want, want], rtol=1e-12)
    assert 179.9 < want < 180.0
    with pytest.warns(led.ObservabilityWarning, match='does not guarantee observability'):
        led.check_observability(1.0 / 91.0 + eps)
    gain = 1.0 / 91.0 + eps
    det, x2f = _det_after_command(gain, 2.0 / gain, 0.0, 2.0)
    assert x2f == pytest.approx(want, rel=1e-12)
    scale = abs(_det_after_command(gain, 2.0 / gain + 1.0, 0.0, 2.0)[0])
    assert abs(det) <= 1e-9 * scale


def test_beyond_the_monotone_range_det_vanishes_at_any_gain():
    # with the default fit unit g'/g decreases only on about [-10.2, 11.7] deg (the two
    # modes of eq. (4) cross further out), so even G <= 1/91 leaves zeros of det C_k there:
    # the guarantee of (24) holds within that range only, and the report says so
    report = led.observability(1.0 / 91.0)
    lo, hi = report.monotone
    assert lo == pytest.approx(-10.2, abs=0.05) and hi == pytest.approx(11.7, abs=0.05)
    assert '[-10.2, 11.7] deg' in report.message
    x2f = np.linspace(-30.0, 30.0, 6001)
    det = np.array([_det_after_command(1.0 / 91.0, x * 91.0 / 90.0, 0.0, 2.0)[0]
                    for x in x2f])
    changes = x2f[np.nonzero(np.diff(np.sign(det)))[0]]
    # the two angles of (17) there: a1 = x2hat^f + psi_k, a2 = x2hat_{k-1} + psi_{k-1}
    a1, a2 = changes + 2.0, changes * 91.0 / 90.0
    outside = (np.minimum(a1, a2) < lo) | (np.maximum(a1, a2) > hi)
    assert changes.size >= 2 and np.all(outside)
    # the printed unit (phi in degrees) is monotone over the whole +-180
    literal = led.observability(0.5, response=led.IncidenceResponse(units_per_degree=1.0))
    assert literal.monotone[0] == pytest.approx(-180.0) and literal.monotone[1] > 179.9


def test_det_vanishes_at_the_paper_gain_at_two_degrees():
    # G = 0.5: x2hat_{k-1} = +-4 deg gives u_{k-1} = -+2, cancelling a +-2 deg scan step, and
    # x2hat^f = +-2 deg: the two rows of C_k coincide, det C_k = 0 exactly
    report = led.observability(0.5)
    assert report.vanishing == (-2.0, 2.0) and not report.guaranteed
    assert 'x2hat^f is -2, +2 deg' in report.message
    with pytest.warns(led.ObservabilityWarning, match=r'\+2'):
        assert led.check_observability(0.5) == report
    for sign in (1.0, -1.0):
        det, x2f = _det_after_command(0.5, 4.0 * sign, 0.0, 2.0 * sign)
        # identical rows: det is 0 up to LU's rounding (LAPACK builds differ: 2e-17 on
        # Ubuntu 24.04's numpy 1.26.4), far below the > 1e-6 of a degree off
        assert x2f == 2.0 * sign and abs(det) <= 1e-12
        # the filter's own Jacobian (17) at that state: identical rows
        ekf = led.ScanningEKF(led.EKFConfig(gain=0.5))
        C = ekf.jacobian(np.array([[2.0, x2f]]), 2.0 * sign, np.array([-2.0 * sign]),
                         np.array([0.0]))
        assert abs(np.linalg.det(C[0])) <= 1e-12 * np.abs(C[0]).max() ** 2
        # one degree off it is not singular
        det, _ = _det_after_command(0.5, 4.0 * sign + 1.0, 0.0, 2.0 * sign)
        assert abs(det) > 1e-6


def test_unusable_gains_and_scans_are_refused():
    for gain in (0.0, -0.1, 2.0, 2.5, float('nan'), float('inf')):
        with pytest.raises(led.ObservabilityError, match='need 0 < G < 2'):
            led.check_observability(gain)
        with pytest.raises(led.ObservabilityError):
            led.ScanningEKF(led.EKFConfig(gain=gain))
    with pytest.raises(led.ObservabilityError, match='must differ'):
        led.observability(0.5, (0.0, 0.0, 2.0))
    with pytest.raises(led.ObservabilityError, match='at least two'):
        led.observability(0.5, (0.0,))
