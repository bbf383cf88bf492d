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
"""The kernels' dispatch: interpreted source against the compiled kernels, and the modes."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from tskf_ros.core import jit, kalman, smoother


def _model(n: int, rng: np.random.Generator) -> tuple:
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    F = np.eye(n) + 0.01 * rng.normal(size=(n, n))
    H = rng.normal(size=(1, n))
    return rng.normal(size=n), P, rng.normal(size=1), H, np.eye(1), np.zeros(1), F, \
        0.01 * np.eye(n), np.zeros(n)


def _interpreted(k: jit.Kernel, *args):
    """Run a kernel's Python source, its nested kernels interpreted as well."""
    kernels = [m for ks in jit._kernels.values() for m in ks]
    saved = [(m, m._call) for m in kernels]
    try:
        for m in kernels:
            m._call = m.interpreted
        return k(*args)
    finally:
        for m, call in saved:
            m._call = call


@pytest.mark.parametrize('n', [1, 2, 6])
def test_the_interpreted_source_gives_the_compiled_kernels_results(n):
    rng = np.random.default_rng(n)
    args = _model(n, rng)
    compiled = kalman.update_predict(*args)
    interpreted = _interpreted(kalman.update_predict, *args)
    for a, b in zip(compiled[:-1], interpreted[:-1]):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    assert compiled[-1] == interpreted[-1] == kalman.OK
    x, P, z, H, R, d = args[:6]
    d2_c, y_c = kalman.mahalanobis2(x, P, z, H, R, d)
    d2_i, y_i = _interpreted(kalman.mahalanobis2, x, P, z, H, R, d)
    assert d2_i == pytest.approx(d2_c, rel=1e-12)
    np.testing.assert_allclose(y_i, y_c, rtol=1e-12)
    # the forms writing into arrays passed in: the same numbers on both paths
    for run in (kalman.update_predict_into, lambda *a: _interpreted(kalman.update_predict_into,
                                                                    *a)):
        out = tuple(np.empty_like(a) for a in compiled[:-1])
        assert run(*args, *out) == kalman.OK
        for a, b in zip(out, compiled[:-1]):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    y_out = np.empty(1)
    assert _interpreted(kalman.mahalanobis2_into, x, P, z, H, R, d, y_out) == \
        pytest.approx(d2_c, rel=1e-12)
    np.testing.assert_allclose(y_out, y_c, rtol=1e-12)
    # the same against FilterPy's equations in numpy: the predicted covariance
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(n) - K @ H
    P_c = I_KH @ P @ I_KH.T + K @ R @ K.T
    F, Q = args[6], args[7]
    np.testing.assert_allclose(interpreted[3], F @ P_c @ F.T + Q, rtol=1e-10)


def test_the_smoother_kernels_interpreted_match():
    rng = np.random.default_rng(7)
    P = np.eye(3) + 0.1 * np.diag(rng.random(3))
    F = np.eye(3) + 0.05 * rng.normal(size=(3, 3))
    P_p = F @ P @ F.T + 0.01 * np.eye(3)
    np.testing.assert_allclose(_interpreted(smoother.smoother_gain, P, F, P_p),
                               smoother.smoother_gain(P, F, P_p), rtol=1e-12)


def test_a_bad_mode_is_refused():
    with pytest.raises(ValueError, match='background'):
        jit.set_mode('fast')


def _run(code: str, **env: str) -> str:
    import os
    result = subprocess.run([sys.executable, '-c', textwrap.dedent(code)], capture_output=True,
                            text=True, env={**os.environ, **env}, timeout=600)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_off_never_imports_numba():
    out = _run("""
        import sys
        import numpy as np
        from tskf_ros.core import kalman
        x, P = np.zeros(2), np.eye(2)
        print(kalman.predict(x, P, P, P, x)[1][0, 0], 'numba' in sys.modules)
        """, TSKF_JIT='off')
    assert out.split() == ['2.0', 'False']


def test_background_runs_the_source_then_switches_to_the_compiled_kernel():
    out = _run("""
        import sys
        import numpy as np
        from tskf_ros.core import jit, kalman
        jit.set_mode('background')
        x, P = np.zeros(2), np.eye(2)
        first = kalman.predict(x, P, P, P, x)
        before = kalman.predict.compiled
        assert jit.ready(timeout=500)
        after = kalman.predict(x, P, P, P, x)
        print(before, kalman.predict.compiled, np.array_equal(first[1], after[1]))
        """, TSKF_AOT='off')
    assert out.split() == ['False', 'True', 'True']


def test_background_compiles_the_kernel_called_not_the_kernels_its_source_calls():
    # update_predict's source calls update and predict: compiled inside update_predict, they
    # get no signature of their own until they are called from outside a kernel
    out = _run("""
        import numpy as np
        from tskf_ros.core import jit, kalman
        jit.set_mode('background')
        x, P, z, H = np.zeros(2), np.eye(2), np.zeros(1), np.ones((1, 2))
        kalman.update_predict(x, P, z, H, np.eye(1), np.zeros(1), P, P, x)
        assert jit.ready(timeout=500)
        print(kalman.update_predict.compiled, len(kalman.update_predict.dispatcher.signatures),
              len(kalman.update.dispatcher.signatures), len(kalman.predict.dispatcher.signatures))
        kalman.predict(x, P, P, P, x)
        assert jit.ready(timeout=500)
        print(kalman.predict.compiled, len(kalman.predict.dispatcher.signatures))
        """, TSKF_AOT='off')
    assert out.split() == ['True', '1', '0', '0', 'True', '1']
