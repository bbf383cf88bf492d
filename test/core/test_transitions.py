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
