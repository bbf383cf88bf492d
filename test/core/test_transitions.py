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

"""The exact transition of tskf_ros.core.transitions (Van Loan's method) against quadrature."""

import numpy as np
import scipy.integrate
import scipy.linalg

from tskf_ros.core.transitions import van_loan


def test_exact_transition_van_loan_matches_quadrature():
    A = np.array([[0.0, 1.0], [-1.0, -2.0]])
    GQGt = np.array([[0.0, 0.0], [0.0, 1.0]])
    mu = 1.7
    F, Qd = van_loan(A, GQGt, mu)
    np.testing.assert_allclose(F, scipy.linalg.expm(A * mu), atol=1e-12)
    ref, _ = scipy.integrate.quad_vec(
        lambda s: scipy.linalg.expm(A * s) @ GQGt @ scipy.linalg.expm(A * s).T, 0, mu,
        epsabs=1e-13)
    np.testing.assert_allclose(Qd, ref, atol=1e-10)


def test_an_overflowing_exponential_is_a_counted_reset_not_a_printed_warning():
    # e^{A mu} of model (3) (A = 1) over 9e5 s overflows inside scipy's expm; its
    # RuntimeWarning would be two raw lines in a node's log: the session's state_health
    # reset already says what happened, once
    import warnings
    from dataclasses import replace

    from tskf_ros.messages.estimator_interface import load_config
    from tskf_ros.owc.session import EstimatorSession
    cfg = replace(load_config().session, transition='exact', max_jump=1e6, max_gap=1e6)
    session = EstimatorSession(cfg)
    ns, t0 = 1_000_000_000, 1_000_000_000_000
    with warnings.catch_warnings():
        warnings.simplefilter('error')          # any warning fails the test
        assert session.add(t0, 300.0).status == 'accepted'
        assert session.add(t0 + ns, 300.0).status == 'accepted'
        assert session.add(t0 + ns + 900_000 * ns, 300.0).status == 'reset'
    assert session.stats.resets['state_health'] == 1


def test_the_stack_of_jittered_mu_is_scipys_expm_and_van_loans_block_exponential():
    # +-5 % jitter around 1 ms and a few long jumps; the reference is scipy's expm of
    # Van Loan's block matrix taken one mu at a time (Van Loan 1978, no doubling)
    from tskf_ros.core.transitions import exact_input_stack, transitions, van_loan_stack
    rng = np.random.default_rng(31)
    A = np.array([[0.0, 1.0], [-40.0, -3.0]])
    GQGt = np.array([[0.1, 0.02], [0.02, 2.0]])
    B = np.array([[0.0], [1.0]])
    mus = np.concatenate([1e-3 * (1 + rng.uniform(-0.05, 0.05, 200)), [0.3, 1.0]])
    F, Qd = van_loan_stack(A, GQGt, mus)
    Bd = exact_input_stack(A, B, mus)
    for k, mu in enumerate(mus):
        M = np.block([[-A, GQGt], [np.zeros((2, 2)), A.T]]) * mu
        E = scipy.linalg.expm(M)
        F_ref = E[2:, 2:].T
        np.testing.assert_allclose(F[k], F_ref, rtol=0, atol=1e-13 * np.abs(F_ref).max())
        Qd_ref = F_ref @ E[:2, 2:]
        np.testing.assert_allclose(Qd[k], Qd_ref, rtol=0, atol=1e-12 * np.abs(Qd_ref).max())
        Bd_ref = scipy.linalg.expm(np.block([[A, B], [np.zeros((1, 3))]]) * mu)[:2, 2:]
        np.testing.assert_allclose(Bd[k], Bd_ref, rtol=0, atol=1e-13 * np.abs(Bd_ref).max())
    # Euler: F = I + mu A, Q_d = mu GQG^T, B_d = mu B, exactly
    eu = transitions('euler', A, GQGt, B, mus)
    np.testing.assert_array_equal(eu.F, np.eye(2) + mus[:, None, None] * A)
    np.testing.assert_array_equal(eu.Qd, mus[:, None, None] * GQGt)
    np.testing.assert_array_equal(eu.Bd, mus[:, None, None] * B)
    assert eu.regressive.all()
    # I + mu A singular at mu = 1 for A = -I: not regressive (Definition 2.12)
    assert not transitions('euler', -np.eye(2), GQGt, B, np.array([1.0, 0.5])).regressive[0]


def test_the_taylor_series_stops_where_the_first_term_left_out_is_below_the_rounding():
    # N terms, the fewest with norm^N / (N + 1)! <= 2^-54: 14 at ||X|| = 1/2 (the most),
    # fewer for the small jumps of jittered stamps; at A = 0 the series still keeps X
    from math import factorial
    from tskf_ros.core.transitions import _taylor_terms
    for norm in (0.5, 0.1, 0.02, 1e-3, 1e-8, 0.0):
        N = _taylor_terms(norm)
        assert norm ** N / factorial(N + 1) <= 2.0 ** -54
        assert N == 1 or norm ** (N - 1) / factorial(N) > 2.0 ** -54
    assert _taylor_terms(0.5) == 14 and _taylor_terms(0.02) == 7 and _taylor_terms(0.0) == 1
    # A = 0: F = I and Q_d = mu GQG^T exactly
    GQGt = np.array([[0.3, 0.1], [0.1, 2.0]])
    F, Qd = van_loan(np.zeros((2, 2)), GQGt, 0.01)
    np.testing.assert_array_equal(F, np.eye(2))
    np.testing.assert_allclose(Qd, 0.01 * GQGt, rtol=1e-15)


def _van_loan_block(A, GQGt, mu):
    """(F, Q_d) from scipy's expm of Van Loan's block matrix (Van Loan 1978), one mu."""
    n = A.shape[0]
    E = scipy.linalg.expm(np.block([[-A, GQGt], [np.zeros((n, n)), A.T]]) * mu)
    F = E[n:, n:].T
    return F, F @ E[:n, n:]


def test_the_series_of_f_and_q_d_is_van_loans_block_exponential_at_every_size():
    # the Taylor series in mu with the model's coefficients made once (van_loan_series),
    # against scipy's expm of the 2n x 2n block: random stable models n = 1, 2, 6, 20,
    # +-5 % jitter around 10 ms and jumps long enough to be halved and doubled back (up to
    # 2 s: beyond, the block's e^{-A mu} grows so large that expm's own error, relative to
    # the whole block, exceeds 1e-12 of F; F is also checked against expm(A mu) alone)
    from tskf_ros.core.transitions import (van_loan_from, van_loan_series, van_loan_stack,
                                           van_loan_stack_from)
    rng = np.random.default_rng(32)
    for n in (1, 2, 6, 20):
        A = rng.normal(size=(n, n)) * 0.3 / np.sqrt(n) - np.eye(n)
        G = rng.normal(size=(n, n))
        GQGt = G @ G.T / n
        mus = np.concatenate([0.01 * (1 + rng.uniform(-0.05, 0.05, 20)), [0.3, 2.0]])
        series = van_loan_series(A, GQGt)
        F, Qd = van_loan_stack_from(*series, mus)
        for k, mu in enumerate(mus):
            F_ref, Qd_ref = _van_loan_block(A, GQGt, mu)
            np.testing.assert_allclose(F[k], F_ref, rtol=0, atol=1e-12 * np.abs(F_ref).max())
            np.testing.assert_allclose(F[k], scipy.linalg.expm(A * mu), rtol=0,
                                       atol=1e-12 * np.abs(F_ref).max())
            np.testing.assert_allclose(Qd[k], Qd_ref, rtol=0,
                                       atol=1e-12 * np.abs(Qd_ref).max())
            # one mu at a time, and from the model alone: the same bits as the stack
            one = van_loan_from(*series, mu)
            np.testing.assert_array_equal(one[0], F[k])
            np.testing.assert_array_equal(one[1], Qd[k])
            np.testing.assert_array_equal(van_loan(A, GQGt, mu)[1], Qd[k])
            assert np.array_equal(Qd[k], Qd[k].T)
        np.testing.assert_array_equal(van_loan_stack(A, GQGt, mus)[0], F)


def test_a_nilpotent_a_gives_the_closed_form_of_the_double_integrator():
    # A = [[0, 1], [0, 0]], G = [0, 1]^T, Q = q: F = [[1, mu], [0, 1]] and
    # Q_d = q [[mu^3 / 3, mu^2 / 2], [mu^2 / 2, mu]] (a white-noise acceleration)
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    q = 0.7
    GQGt = np.array([[0.0, 0.0], [0.0, q]])
    for mu in (1e-3, 0.0101, 1.0, 5.0, 60.0):
        F, Qd = van_loan(A, GQGt, mu)
        np.testing.assert_allclose(F, [[1.0, mu], [0.0, 1.0]], rtol=1e-14, atol=0)
        ref = q * np.array([[mu ** 3 / 3, mu ** 2 / 2], [mu ** 2 / 2, mu]])
        np.testing.assert_allclose(Qd, ref, rtol=1e-13, atol=0)
