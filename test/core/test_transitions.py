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
