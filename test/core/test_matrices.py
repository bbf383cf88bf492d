"""The covariance and invertibility checks of tskf_ros.core.matrices against eigenvalues."""

import numpy as np

from tskf_ros.core.matrices import is_invertible, is_psd


def test_fast_psd_and_invertibility_checks_agree_with_eigenvalues():
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 4):
        for _ in range(200):
            M = rng.normal(size=(n, n))
            P = M @ M.T + rng.normal() * np.eye(n)     # sometimes indefinite
            lam = np.linalg.eigvalsh(P)[0]
            scale = max(1.0, np.max(np.abs(np.diag(P))))
            if abs(lam) > 1e-6 * scale:                # away from the tolerance band
                assert is_psd(P) == (lam > 0)
            A = rng.normal(size=(n, n))
            assert is_invertible(A) == (np.linalg.cond(A) < 1e10)
    singular = np.array([[1.0, 1.0], [-1.0, -1.0]])      # I + A of Example 3.20 on Z
    assert not is_invertible(singular) and not is_invertible(1e6 * singular)
    assert is_invertible(1e-6 * np.eye(3))                # scale does not matter
