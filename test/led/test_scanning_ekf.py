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

"""The scanning EKF of Solanki et al. 2018 (Section IV): Jacobian (17), observability, EKF."""

import warnings

import numpy as np
import pytest
from solanki_paper import dg_paper, g_paper

from tskf_ros import led


def h_paper(x, psi, shift, psi_prev, s):
    """Eq. (16) written here: [x1 g(x2 + psi_k), x1 g(x2 - shift + psi_{k-1})] in degrees."""
    return np.stack([x[:, 0] * g_paper(s * (x[:, 1] + psi)),
                     x[:, 0] * g_paper(s * (x[:, 1] - shift + psi_prev))], axis=-1)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(4)
    ekf = led.ScanningEKF(runs=50)
    s = ekf.response.units_per_degree
    x = np.column_stack([rng.uniform(0.5, 4.0, 50), rng.uniform(-20.0, 20.0, 50)])
    shift = rng.uniform(-5.0, 5.0, 50)
    psi_prev = rng.choice(led.SCAN_ANGLES, 50)
    psi = 6.0
    C = ekf.jacobian(x, psi, shift, psi_prev)
    np.testing.assert_allclose(ekf.h(x, psi, shift, psi_prev),
                               h_paper(x, psi, shift, psi_prev, s), rtol=1e-12)
    eps = 1e-6
    for j in range(2):
        dx = np.zeros(2)
        dx[j] = eps
        numeric = (h_paper(x + dx, psi, shift, psi_prev, s)
                   - h_paper(x - dx, psi, shift, psi_prev, s)) / (2 * eps)
        np.testing.assert_allclose(C[:, :, j], numeric, rtol=1e-5, atol=1e-8)


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


class ReferenceEKF:
    """
    One run of the scanning EKF, eq. (13)-(21), written here from the paper (Table I).

    Predict x2 += u_{k-1}, P += mu Q; update with the pair (12) [z_k, z_prev] (the first
    measurement alone), K = P C^T S^-1, P = (I - K C) P; u_k = -G x2; command
    u_k + psi_{k+1} - psi_k.  A missing z only predicts.
    """

    def __init__(self, s):
        self.s = s
        self.x, self.P = np.array([2.0, 0.0]), np.diag([100.0, 1000.0])
        self.Q, self.R, self.G = np.diag([0.25, 1.0]), np.eye(2), 0.5
        self.scan = [-2.0, -4.0, -6.0, -8.0, -10.0, -8.0, -6.0, -4.0, -2.0, 0.0,
                     2.0, 4.0, 6.0, 8.0, 10.0, 8.0, 6.0, 4.0, 2.0, 0.0]
        self.k, self.t, self.u, self.since = 0, None, 0.0, 0.0
        self.z_prev = self.psi_prev = None
        self.det = None

    def row(self, angle):
        return np.array([g_paper(self.s * angle), self.x[0] * self.s * dg_paper(self.s * angle)])

    def step(self, t, z):
        if self.t is not None:
            mu = (t - self.t) / 0.05
            self.x[1] += self.u
            self.P = self.P + mu * self.Q
        self.t = t
        psi = self.scan[self.k % 20]
        if z is not None:
            x1, x2 = self.x
            rows = [self.row(x2 + psi)]
            res = [z - x1 * g_paper(self.s * (x2 + psi))]
            if self.z_prev is not None:
                a2 = x2 - self.since + self.psi_prev
                rows.append(self.row(a2))
                res.append(self.z_prev - x1 * g_paper(self.s * a2))
            C = np.array(rows)
            R = self.R[:len(rows), :len(rows)]
            K = self.P @ C.T @ np.linalg.inv(C @ self.P @ C.T + R)
            self.x = self.x + K @ np.array(res)
            self.P = (np.eye(2) - K @ C) @ self.P
            self.det = np.linalg.det(C) if len(rows) == 2 else None
            self.z_prev, self.psi_prev, self.since = z, psi, 0.0
        self.u = -self.G * self.x[1]
        self.since += self.u
        self.k += 1
        return self.u + self.scan[self.k % 20] - psi


def test_ekf_equals_the_paper_written_out():
    rng = np.random.default_rng(8)
    ekf = led.ScanningEKF()
    ref = ReferenceEKF(ekf.response.units_per_degree)
    t, phi = 10.0, 4.0
    for k in range(60):
        t += 0.05 * (3 if k in (20, 41) else 1)          # two gaps: mu = 3
        clean = 2.0 * g_paper(17.697 * phi)
        z = None if k in (7, 30, 31) else float(clean + 0.2 * rng.standard_normal())
        cmd = ekf.step(t, z)
        want = ref.step(t, z)
        assert cmd[0] == pytest.approx(want, rel=1e-7, abs=1e-9), k
        np.testing.assert_allclose(ekf.x[0], ref.x, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(ekf.P[0], ref.P, rtol=1e-6, atol=1e-8 * np.abs(ref.P).max())
        if z is not None and ref.det is not None:
            assert ekf.det[0] == pytest.approx(ref.det, rel=1e-7, abs=1e-12)
        phi += 0.06 + want + 0.1 * rng.standard_normal()


def test_paper_gain_runs_with_nonzero_det_away_from_two_degrees():
    ekf = led.ScanningEKF(led.EKFConfig(gain=0.5), runs=3)
    refs = [ReferenceEKF(ekf.response.units_per_degree) for _ in range(3)]
    for t, z in ((0.0, [2.0, 2.5, 3.0]), (0.05, [2.2, 2.4, 2.9])):
        ekf.step(t, z)
        for ref, zi in zip(refs, z):
            ref.step(t, zi)
    # det C_k of (17) at the second step, from the paper's rows written out
    np.testing.assert_allclose(ekf.det, [ref.det for ref in refs], rtol=1e-7)
    assert np.all(np.abs(ekf.det) > 1e-3) and not ekf.singular.any()


def test_step_interface_for_a_node():
    ekf = led.ScanningEKF()
    first = ekf.step(10.0, 2.5)
    # the first measurement alone (no pair): x1 = 2, x2 = 0 at psi_0 = -2 deg
    s = ekf.response.units_per_degree
    c = np.array([g_paper(-2.0 * s), 2.0 * s * dg_paper(-2.0 * s)])
    P0 = np.diag([100.0, 1000.0])
    K = P0 @ c / (c @ P0 @ c + 1.0)
    x = np.array([2.0, 0.0]) + K * (2.5 - 2.0 * g_paper(-2.0 * s))
    # command u_0 + psi_1 - psi_0 = -0.5 x2 + (-4) - (-2)
    assert first.shape == (1,)
    assert first[0] == pytest.approx(-0.5 * x[1] - 2.0, rel=1e-9)
    np.testing.assert_allclose(ekf.x[0], x, rtol=1e-9)
    ekf.step(10.05, None)
    ekf.step(10.10, float('nan'))
    with pytest.raises(led.AlignmentError, match='stale stamp'):
        ekf.step(10.10, 2.0)


def test_gap_prediction_uses_the_stamps():
    a, b = led.ScanningEKF(), led.ScanningEKF()
    for ekf in (a, b):
        ekf.step(0.0, 2.0)
        ekf.step(0.05, 2.6)
    P_post = a.P.copy()
    applied = [a.u[0]]
    for k in (2, 3, 4):          # a: one call per missing sample
        a.step(0.05 * k, None)
        applied.append(a.u[0])
    b.step(0.20, None)           # b: a single call after the gap, mu = 3
    np.testing.assert_allclose(a.P_prior, P_post + 3.0 * a.Q)
    np.testing.assert_allclose(b.P_prior, P_post + 3.0 * b.Q)
    # the next measurement is paired with the last one, shifted by the control since
    assert a.since[0] == pytest.approx(sum(applied))
    assert not a.updated.any()
