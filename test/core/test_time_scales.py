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

"""Time scales against Bohner & Wintz Table 4 and Cai et al. Section IV-C."""

import numpy as np
import pytest

from tskf_ros.core import time_scales as ts


def test_table_4_graininess():
    np.testing.assert_allclose(ts.h_integers(0.5, 6).mu()[:-1], 0.5)
    # {H_n}: mu(H_n) = 1 / (n + 1)
    n = np.arange(9)
    np.testing.assert_allclose(ts.harmonic(10).mu()[:-1], 1.0 / (n + 1))
    # q^Z: mu(t) = (q - 1) t, sigma(t) = q t
    q = ts.q_integers(1.5, -3, 5)
    np.testing.assert_allclose(q.mu()[:-1], 0.5 * q.points[:-1])
    np.testing.assert_allclose(q.sigma()[:-1], 1.5 * q.points[:-1])
    # N_0^2: mu(t) = 1 + 2 sqrt(t)
    s = ts.squares(8)
    np.testing.assert_allclose(s.mu()[:-1], 1 + 2 * np.sqrt(s.points[:-1]))
    # backward graininess
    np.testing.assert_allclose(s.nu(), np.r_[0, 1 + 2 * np.sqrt(s.points[:-1])])


def test_p_ab_theoretical_graininess():
    p = ts.p_ab(1.0, 2.0, 3, dense_step=0.25)
    # mu = 0 on [kc, kc + a), b at kc + a, c = 3
    m = p.mu_theory()
    for t, mu in zip(p.points[:-1], m[:-1]):
        expected = 2.0 if np.isclose(t % 3.0, 1.0) else 0.0
        assert mu == pytest.approx(expected)
    assert p.points[-1] == pytest.approx(7.0)
    np.testing.assert_allclose(p.mu()[:-1][p.dense], 0.25)


def test_cai_t3_is_2z_then_harmonic_numbers():
    t3 = ts.cai_t3(12)
    np.testing.assert_allclose(t3.points[:5], [0, 2, 4, 6, 8])
    # after 8: consecutive harmonic numbers H_n > 8, with mu = 1 / (n + 1)
    h = t3.points[5:]
    n0 = int(np.argmax(np.cumsum(1.0 / np.arange(1, 5000)) > 8.0)) + 1
    ref = np.sum(1.0 / np.arange(1, n0 + 1))
    assert h[0] == pytest.approx(ref, rel=1e-12)
    np.testing.assert_allclose(np.diff(h), 1.0 / (n0 + 1 + np.arange(h.size - 1)), rtol=1e-9)


def test_cai_td_structure_and_its_jumps_are_recovered_from_data():
    td = ts.cai_td(0.1)
    assert td.points[0] == 1.0 and td.points[-1] == 300.0
    assert ts.jumps(td.points, period=1.0) == [(32.0, 2.0), (128.0, 2.0), (135.0, 4.0),
                                               (212.0, 3.0), (224.0, 6.0)]
    segs = ts.classify(td.points, period=1.0)
    kinds = [s.kind for s in segs]
    # Cai's list: 20 pieces, 5 jumps between them; [1,15) and {15..21} etc. alternate
    assert kinds.count('jump') == 5
    assert [(s.start, s.end) for s in segs if s.kind == 'discrete'] == [
        (15, 21), (62, 67), (75, 81), (83, 86), (135, 154), (173, 204), (224, 238),
        (273, 285)]
    assert max(td.mu()) == 6.0
    # the dense step of T_d is the configured one
    np.testing.assert_allclose(td.mu()[:-1][td.dense], 0.1, atol=1e-9)


def test_classifier_on_a_1hz_stream_with_random_drops():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 600.0)
    keep = rng.random(t.size) > 0.2
    keep[0] = keep[-1] = True
    s = t[keep]
    found = ts.jumps(s, period=1.0)
    # independent: a jump ends at every kept sample whose predecessor was dropped
    dropped_before = [(s[i], s[i] - s[i - 1]) for i in range(1, s.size) if s[i] - s[i - 1] > 1]
    assert found == dropped_before
    assert all(j == int(j) and j >= 2 for _, j in found)


def test_bad_time_scales_are_refused():
    with pytest.raises(ts.TimeScaleError, match='increase strictly'):
        ts.discrete([0.0, 1.0, 1.0])
    with pytest.raises(ts.TimeScaleError, match='increase strictly'):
        ts.classify([0.0, 2.0, 1.0], period=1.0)
    with pytest.raises(ts.TimeScaleError, match='period'):
        ts.classify([0.0, 1.0], period=0.0)
    with pytest.raises(ts.TimeScaleError, match='finite'):
        ts.discrete([0.0, float('nan')])


def test_readme_numbers_of_t3_and_t_d():
    # README: 'after 8 come the harmonic numbers above 8 (H_1674 = 8.0005, ...), with
    # mu ~ 6e-4'; a measurement there has variance R / mu, 'about 1700 R'
    t3 = ts.cai_t3(12)
    H = np.cumsum(1.0 / np.arange(1, 1676))
    assert H[1672] <= 8.0 < H[1673]                   # H_1673 <= 8 < H_1674
    assert t3.points[5] == pytest.approx(H[1673], rel=1e-12)
    assert t3.points[5] == pytest.approx(8.0005, abs=5e-5)
    mu = t3.mu()[5]
    assert mu == pytest.approx(1 / 1675, rel=1e-9) and mu == pytest.approx(6e-4, abs=5e-5)
    assert 1 / mu == pytest.approx(1700, abs=50)
    # 'a measurement on a dense stretch realised at 0.1 s has variance 10 R'
    td = ts.cai_td(0.1)
    np.testing.assert_allclose(1 / td.mu()[:-1][td.dense], 10.0, rtol=1e-9)
    # 'over T_d's 300 s a truth simulated from (3) reaches e^250': prod (1 + mu) = e^250.96
    growth = np.sum(np.log1p(td.mu()[:-1]))
    assert 250.0 <= growth < 251.0
