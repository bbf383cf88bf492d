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

"""The kernels compiled ahead of time against numba's dispatchers of the same sources."""

import os
from pathlib import Path
import shutil
import subprocess
import sys
import sysconfig
import textwrap

import numpy as np
import pytest

from tskf_ros.core import aot, kalman, transitions


@pytest.fixture(scope='module')
def built():
    module = aot.load()
    if module is None:      # ./run builds it; else once here (about a minute)
        pytest.skip('the ahead-of-time module is not built: python -m tskf_ros.core.aot')
    return module


def _step_args(n: int, rng: np.random.Generator) -> tuple:
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    H = rng.normal(size=(1, n))
    Fk, Dk, norm = transitions.van_loan_series(-np.eye(n) + 0.1 * A, 0.01 * np.eye(n))
    return (rng.normal(size=n), P, rng.normal(size=1), H, 0.1 * np.eye(1), np.zeros(1),
            -np.eye(n) + 0.1 * A, 0.01 * np.eye(n), np.zeros((n, 1)), Fk, Dk, norm)


@pytest.mark.parametrize('n', [1, 2, 3, 6])
@pytest.mark.parametrize('exact', [False, True])
def test_the_step_over_a_new_mu_is_numbas_to_the_bit(built, n, exact):
    rng = np.random.default_rng(10 * n + exact)
    args = _step_args(n, rng) + (1e-3 * (1 + 0.01 * rng.uniform(-1, 1)), exact)
    ahead = built.transitions__jump_update_predict(*args)
    jitted = transitions.jump_update_predict.dispatcher(*args)
    for a, b in zip(ahead[0], jitted[0]):
        np.testing.assert_array_equal(a, b)
    assert ahead[1] == jitted[1]


@pytest.mark.parametrize('n', [1, 2, 3, 6])
def test_the_other_node_kernels_are_numbas_to_the_bit(built, n):
    rng = np.random.default_rng(n)
    x, P, z, H, R, d, A, GQGt, B = _step_args(n, rng)[:9]
    F, Q, _, _ = transitions.euler(A, GQGt, B, 1e-3)
    for name, args in (('update_predict', (x, P, z, H, R, d, F, Q, np.zeros(n))),
                       ('mahalanobis2', (x, P, z, H, R, d)),
                       ('euler', (A, GQGt, B, 1e-3)),
                       ('update_batch', (x[None], P[None], z[None], H[None], R[None],
                                         d[None]))):
        module = 'transitions' if name == 'euler' else 'kalman'
        ahead = getattr(built, f'{module}__{name}')(*args)
        jitted = getattr(kalman if module == 'kalman' else transitions,
                         name).dispatcher(*args)
        for a, b in zip(ahead, jitted):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize('n', [1, 2, 3, 6])
def test_the_kernels_writing_into_arrays_are_numbas_to_the_bit(built, n):
    rng = np.random.default_rng(20 + n)
    x, P, z, H, R, d, A, GQGt, B = _step_args(n, rng)[:9]
    F, Q, _, _ = transitions.euler(A, GQGt, B, 1e-3)
    shapes = ((n,), (n, n), (n,), (n, n), (1,), (1, 1))
    ahead, jitted = (tuple(np.full(s, np.nan) for s in shapes) for _ in range(2))
    args = (x, P, z, H, R, d, F, Q, np.zeros(n))
    assert built.kalman__update_predict_into(*args, *ahead) == \
        kalman.update_predict_into.dispatcher(*args, *jitted) == kalman.OK
    for a, b in zip(ahead, jitted):
        np.testing.assert_array_equal(a, b)
    y_ahead, y_jitted = np.full(1, np.nan), np.full(1, np.nan)
    assert built.kalman__mahalanobis2_into(*args[:6], y_ahead) == \
        kalman.mahalanobis2_into.dispatcher(*args[:6], y_jitted)
    np.testing.assert_array_equal(y_ahead, y_jitted)


def test_an_array_to_write_that_is_read_only_or_of_another_shape_is_refused(built):
    # in a process of its own: a write out of bounds would crash it
    out = _run(_handed_on('mahalanobis2_into', 'np.zeros(1)') + """
        print('read-only', call(x, P, z, H, R, d, readonly), handed, readonly[0])
        for y in (np.zeros(2), np.zeros(0)):
            try:
                call(x, P, z, H, R, d, y)
            except ValueError as exc:
                print('shape', y.size, 'ValueError' if 'shape' in str(exc) else exc, y.sum())
        y = np.zeros(1)
        print('written', call(x, P, z, H, R, d, y), y[0])
        """)
    # y = 1, S = H P H^T + R = 3: d^2 = 1 / 3
    assert out.splitlines() == ["read-only None ['TypeError'] 0.0", 'shape 2 ValueError 0.0',
                                'shape 0 ValueError 0.0', f'written {1 / 3!r} 1.0']


def test_a_module_of_other_sources_is_not_loaded(tmp_path, monkeypatch):
    for name in aot.SOURCES:
        (tmp_path / name).write_bytes((aot.CORE / name).read_bytes())
    monkeypatch.setattr(aot, 'CORE', tmp_path)
    same = aot.digest()
    (tmp_path / 'kalman.py').write_bytes((aot.CORE / 'kalman.py').read_bytes() + b'\n# ')
    assert aot.digest() != same


def _run(code: str) -> str:
    result = subprocess.run([sys.executable, '-c', textwrap.dedent(code)],
                            capture_output=True, text=True, env=dict(os.environ), timeout=600)
    assert result.returncode == 0, result.stderr
    return result.stdout


def _handed_on(kernel: str, readonly: str) -> str:
    """
    Return code that makes `call`, aot's call of a gate kernel, and its arguments.

    `call` records in `handed` what it hands on; x, P, z, H, R, d are the gate's arguments,
    `readonly` a read-only array.
    """
    return f"""
        import numpy as np
        from tskf_ros.core import aot
        handed = []
        call = aot.function('tskf_ros.core.kalman', {kernel!r},
                            lambda args, error: handed.append(type(error).__name__))
        x, P, z, H, R, d = np.zeros(2), np.eye(2), np.ones(1), np.ones((1, 2)), np.eye(1), \\
            np.zeros(1)
        readonly = {readonly}
        readonly.flags.writeable = False
        """


def test_a_node_step_runs_ahead_of_time_without_numba(built):
    out = _run("""
        import sys
        import numpy as np
        from tskf_ros.core import jit, kalman
        jit.set_mode('background')
        x, P, z, H = np.zeros(2), np.eye(2), np.zeros(1), np.ones((1, 2))
        step = kalman.update_predict(x, P, z, H, np.eye(1), np.zeros(1), P, P, x)
        print(repr(kalman.update_predict).endswith('(compiled ahead of time)>'),
              'numba' in sys.modules, step[-1])
        """)
    assert out.split() == ['True', 'False', '0']


def test_arguments_of_other_types_fall_back_to_numba(built):
    # a strided H: not the layout built ahead of time; compiled by numba in the background
    out = _run("""
        import numpy as np
        from tskf_ros.core import jit, kalman
        jit.set_mode('background')
        x, P, z, H = np.zeros(2), np.eye(2), np.ones(1), np.ones((1, 4))[:, ::2]
        first = kalman.mahalanobis2(x, P, z, H, np.eye(1), np.zeros(1))
        assert jit.ready(timeout=500)
        print(kalman.mahalanobis2.compiled, first[0],
              kalman.mahalanobis2(x, P, z, H, np.eye(1), np.zeros(1))[0])
        """)
    # y = 1, S = H P H^T + R = 3: d^2 = 1 / 3
    assert out.split() == ['True', repr(1 / 3), repr(1 / 3)]


# the build of a package (setup.py runs `python -m tskf_ros.core.aot --if-possible`)

def _hide_numba(tmp_path) -> dict:
    """Return an environment whose Python finds a numba that does not import."""
    hidden = tmp_path / 'hide'
    (hidden / 'numba').mkdir(parents=True)
    (hidden / 'numba' / '__init__.py').write_text(
        "raise ImportError(\"No module named 'numba'\")\n")
    return dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(hidden)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))


def test_without_numba_the_build_says_one_line_and_succeeds(tmp_path):
    result = subprocess.run(
        [sys.executable, '-m', 'tskf_ros.core.aot', '--if-possible', '--output',
         str(tmp_path / 'out')],
        capture_output=True, text=True, env=_hide_numba(tmp_path), timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ''
    lines = result.stdout.splitlines()
    assert len(lines) == 1, result.stdout
    assert lines[0].startswith('numba is not installed')
    assert 'in the background' in lines[0] and 'python3-numba-pip' in lines[0]
    assert not (tmp_path / 'out').exists()


def test_without_a_compiler_the_build_says_one_line(tmp_path, monkeypatch):
    pytest.importorskip('numba', reason='numba is not installed')
    monkeypatch.setenv('CC', 'no-such-compiler-tskf')
    path, line = aot.build_if_possible(tmp_path)
    assert path is None
    assert line.startswith('no C compiler (no-such-compiler-tskf)'), line
    assert '\n' not in line and list(tmp_path.iterdir()) == []


def test_the_switch_off_skips_the_build(tmp_path, monkeypatch):
    monkeypatch.setenv(aot.SWITCH, 'off')
    path, line = aot.build_if_possible(tmp_path)
    assert path is None and line.startswith('TSKF_AOT=off'), line


def test_a_module_already_built_is_not_built_again(tmp_path):
    pytest.importorskip('numba', reason='numba is not installed')
    (tmp_path / aot.filename()).write_bytes(b'')
    path, line = aot.build_if_possible(tmp_path)
    assert path == tmp_path / aot.filename()
    assert line.endswith(str(path))


def test_a_build_cut_short_leaves_no_module(tmp_path, monkeypatch):
    numba_pycc = pytest.importorskip('numba.pycc', reason='numba is not installed')

    def cut_short(self):
        (Path(self.output_dir) / aot.filename()).write_bytes(b'half')   # what a kill leaves
        raise KeyboardInterrupt     # raised through the build as a Ctrl-C would be

    monkeypatch.setattr(numba_pycc.CC, 'compile', cut_short)
    with pytest.raises(KeyboardInterrupt):
        aot.build(tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_numba_pycc_is_pending_deprecation_only():
    # numba removes pycc only after DeprecationWarnings over at least two releases (its
    # deprecation notices); this fails when that clock starts (doc/installation.md)
    pytest.importorskip('numba', reason='numba is not installed')
    result = subprocess.run([sys.executable, '-W', 'always', '-c', 'import numba.pycc'],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert 'NumbaPendingDeprecationWarning' in result.stderr
    assert 'NumbaDeprecationWarning' not in result.stderr


@pytest.mark.slow
def test_the_package_build_step_makes_a_loadable_module(tmp_path):
    pytest.importorskip('numba', reason='numba is not installed: no module to build')
    compiler = (os.environ.get('CC') or sysconfig.get_config_var('CC') or 'cc').split()[0]
    if shutil.which(compiler) is None:
        pytest.skip(f'no C compiler ({compiler}): no module to build')
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / 'numba_cache'))
    result = subprocess.run(
        [sys.executable, '-m', 'tskf_ros.core.aot', '--if-possible', '--output',
         str(tmp_path / 'out')], capture_output=True, text=True, env=env, timeout=900)
    assert result.returncode == 0, result.stderr
    built = tmp_path / 'out' / aot.filename()
    assert result.stdout.splitlines() == [f"the nodes' kernels compiled ahead of time: {built}"]
    out = _run(f"""
        import os, sys
        os.environ['{aot.ENVIRONMENT}'] = {str(tmp_path / 'out')!r}
        from tskf_ros.core import aot
        module = aot.load()
        print(module.__file__ == {str(built)!r}, 'numba' in sys.modules)
        """)
    assert out.split() == ['True', 'False']


def test_the_call_takes_only_the_types_built_and_hands_any_other_on(built):
    # in a process of its own: an argument the compiled form would misread crashes it
    out = _run(_handed_on('mahalanobis2', 'np.eye(1)') + """
        tagged = np.dtype(np.float64, metadata={'unit': 'mW'})  # equal, not numpy's own
        cases = {
            'float32 x': (x.astype(np.float32), P, z, H, R, d),
            'int64 P': (x, np.eye(2, dtype=np.int64), z, H, R, d),
            'big-endian P': (x, np.eye(2).astype('>f8'), z, H, R, d),
            'P as a vector': (x, np.ones(4), z, H, R, d),
            'P as a stack': (x, np.eye(2)[None], z, H, R, d),
            'strided H': (x, P, z, np.ones((1, 4))[:, ::2], R, d),
            'reversed x': (x[::-1], P, z, H, R, d),
            'read-only R': (x, P, z, H, readonly, d),
            'a matrix H': (x, P, z, np.asmatrix(H), R, d),
            'a list z': (x, P, [1.0], H, R, d),
            'five arguments': (x, P, z, H, R),
            'seven arguments': (x, P, z, H, R, d, d),
        }
        for name, args in cases.items():
            handed.clear()
            result = call(*args)
            print(name.replace(' ', '_'), result is None and handed == ['TypeError'])
        d2, y = call(x, P, z, H.astype(tagged), R, d)
        print('equal_dtype', handed == ['TypeError'] and d2 == 1 / 3)
        """)
    # every other type handed on, none run compiled; an equal dtype runs compiled:
    # y = 1, S = H P H^T + R = 3, d^2 = 1 / 3
    assert [line.split()[1] for line in out.splitlines()] == ['True'] * 13


def test_a_scalar_of_another_type_is_handed_on(built):
    out = _run("""
        import numpy as np
        from tskf_ros.core import aot
        handed = []
        call = aot.function('tskf_ros.core.transitions', 'euler',
                            lambda args, error: handed.append(type(error).__name__))
        A = -np.eye(2)
        print(call(A, A, A[:, :1], 'a millisecond'), handed)
        """)
    assert out.split() == ['None', "['TypeError']"]


def test_a_wrong_dtype_through_the_kernel_gets_numbas_result(built):
    out = _run("""
        import numpy as np
        from tskf_ros.core import jit, kalman
        jit.set_mode('background')
        x, P, z, H = np.zeros(2), np.eye(2), np.ones(1), np.ones((1, 2))
        first = kalman.mahalanobis2(x.astype(np.float32), P, z, H, np.eye(1), np.zeros(1))
        print(repr(kalman.mahalanobis2).endswith('(compiled ahead of time)>'), first[0])
        """)
    # the float32 call ran numba's way (its source until compiled): d^2 = 1 / 3
    assert out.split() == ['False', repr(1 / 3)]
