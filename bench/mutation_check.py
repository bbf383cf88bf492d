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

"""
Mutation check of the test suite: a small, plausible bug in the core must make a test fail.

    .venv/bin/python bench/mutation_check.py            # every mutation
    .venv/bin/python bench/mutation_check.py --only M6 M11 --keep

Not part of CI (it takes a couple of minutes).  It copies tskf_ros/, test/, config/ and the
packaging files into a temporary directory, checks that Python there imports the copy's
tskf_ros (not the editable install of this checkout), runs the relevant tests once
unmutated (they must pass), then for each mutation replaces one exact snippet in the copy,
runs those tests with `-x -q` and restores the file.  The checkout itself is never
written.  A snippet that is not found exactly once is a stale mutation: the script stops
with exit code 2 before running anything.  Exit code 0 when every mutation is caught.
"""

import argparse
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Optional

REPO = Path(__file__).resolve().parent.parent
COPIED = ('tskf_ros', 'test', 'config', 'setup.cfg', 'setup.py', 'package.xml', 'resource')
IGNORED = shutil.ignore_patterns('__pycache__', '*.pyc', '.pytest_cache')


@dataclass(frozen=True)
class Mutation:
    """One bug: in `path`, replace `original` (found exactly once) by `replacement`."""

    name: str
    what: str
    path: str
    original: str
    replacement: str
    tests: tuple
    k: Optional[str] = None

    def pytest_args(self) -> list:
        """Return the pytest arguments selecting the tests that should catch it."""
        return list(self.tests) + (['-k', self.k] if self.k else [])


KALMAN = 'tskf_ros/core/kalman.py'
KF = 'tskf_ros/core/timescale_kalman.py'
TRANSITIONS = 'tskf_ros/core/transitions.py'
SWITCHING = 'tskf_ros/core/irregular/switching.py'
INTERVALS = 'tskf_ros/owc/session/sampling_intervals.py'
ADMISSION = 'tskf_ros/owc/session/admission.py'
EKF = 'tskf_ros/led/scanning_ekf.py'
CORE_TESTS = ('test/core/test_kalman.py', 'test/core/test_timescale_kalman.py')

MUTATIONS = (
    Mutation('M6', 'Theorem 2 diagnostics with R instead of R / period', INTERVALS,
             'float(kf.R[0, 0]) / self.period,', 'float(kf.R[0, 0]),',
             ('test/owc/session/test_sampling_intervals.py',), 'sampling_intervals'),
    Mutation('M10', "Cai's T_d measurement noise not scaled by 1 / mu",
             'tskf_ros/experiments/reproduce.py',
             "vscale = 1.0 / np.sqrt(mu_meas) if noise_scaling == 'theory' else "
             'np.ones(mu.size)',
             'vscale = np.ones(mu.size)',
             ('test/experiments/test_reproduce.py',), 'cai_td'),
    Mutation('M11', 'theorem1().stable ignores detectability (A1)',
             'tskf_ros/core/irregular/theorem1.py',
             'return self.detectable and not self.degenerate', 'return not self.degenerate',
             ('test/core/irregular/test_theorem1.py',), 'theorem1'),
    Mutation('K1', 'innovation sign of the offset: y = z - (H x - d)', KALMAN,
             'y = z - (_mv(H, x) + d)', 'y = z - (_mv(H, x) - d)', CORE_TESTS),
    Mutation('T2', "simulate_truth: measurement noise not scaled by 1 / mu ('theory')",
             'tskf_ros/core/linear_models.py',
             "vscale = 1.0 / np.sqrt(mu_meas) if noise_scaling == 'theory' else np.ones(N)",
             'vscale = np.ones(N)',
             ('test/experiments/test_reproduce.py',), 'simulate_truth or example_320_readme'),
    Mutation('K3', 'R_d = R instead of R / mu (the corrected gain without its mu)', KF,
             'return R / mu', 'return R', CORE_TESTS),
    Mutation('K4', 'Joseph form: K R K^T dropped from the updated covariance', KALMAN,
             'KS = _mm(K, S)', 'KS = _mm(K, S - R)', CORE_TESTS),
    Mutation('K5', "Van Loan's integral: Q_d series of A Q_d - Q_d A^T", TRANSITIONS,
             'Dk[k] = (XD + XD.T) / k', 'Dk[k] = (XD - XD.T) / k',
             ('test/core/test_transitions.py',), 'van_loan'),
    Mutation('T1', "simulate_truth: process noise scaled by mu instead of sqrt(mu) ('theory')",
             'tskf_ros/core/linear_models.py',
             "scale = np.sqrt(mu[k]) if noise_scaling == 'theory' else mu[k]",
             'scale = mu[k]',
             ('test/experiments/test_reproduce.py',), 'simulate_truth'),
    Mutation('I1', 'lifted filter: Phi = A^(kappa - 1) (off by one)', SWITCHING,
             'Phi = powers[kappa]', 'Phi = powers[kappa - 1]',
             ('test/core/irregular/test_switching.py',), 'lifted'),
    Mutation('I2', 'pathological intervals stop one short (range off by one)',
             'tskf_ros/core/irregular/intervals.py',
             'for kappa in range(2, max_interval + 1):', 'for kappa in range(2, max_interval):',
             ('test/core/irregular/test_intervals.py',), 'pathological or rotation or plus_minus'),
    Mutation('I3', 'switching filter: time update without the process noise Q (eq. (14))',
             SWITCHING, 'kalman.predict(self.x, self.P, self.A, self.Q,',
             'kalman.predict(self.x, self.P, self.A, 0.0 * self.Q,',
             ('test/core/irregular/test_switching.py',
              'test/core/irregular/test_theorem2.py')),
    Mutation('I4', 'jump_covariance weighs the pre-jump measurement by R / h, not R / J',
             'tskf_ros/core/irregular/after_jump.py',
             'return _predict(_correct(P, C, R / J), F_J, Q_J)',
             'return _predict(_correct(P, C, R / period), F_J, Q_J)',
             ('test/core/irregular/test_after_jump.py',), 'jump_covariance'),
    Mutation('S1', 'session: sampling interval in periods off by one', INTERVALS,
             'return int(round(dt / self.period))', 'return int(round(dt / self.period)) + 1',
             ('test/owc/session/test_sampling_intervals.py',), 'sampling_intervals'),
    Mutation('S2', 'session: readings <= 0 no longer rejected as interruptions', ADMISSION,
             'if not lowest > self.low:', 'if False:',
             ('test/owc/session/test_admission.py',), 'bad_samples'),
    Mutation('E1', "scanning EKF: wrong sign of C_k,1,2 = x1 g'(x2 + psi_k)", EKF,
             'C[:, 0, 1] = x[:, 0] * dg(a1)', 'C[:, 0, 1] = -x[:, 0] * dg(a1)',
             ('test/led/test_scanning_ekf.py',)),
    Mutation('E2', 'scanning EKF: the measurement noise R left out of the update (eq. (19))',
             EKF, 'y + hx, C, R, d)', 'y + hx, C, 0.0 * R, d)',
             ('test/led/test_scanning_ekf.py',)),
    Mutation('E3', 'scanning EKF: mu dropped from the prediction over a gap (eq. (14))', EKF,
             'self.P = self.P + mu * self.Q', 'self.P = self.P + self.Q',
             ('test/led/test_scanning_ekf.py',)),
    Mutation('E4', "eq. (4)'s derivative with the wrong sign of its first mode",
             'tskf_ros/led/intensity_model.py',
             'return s * (-2.0 * a1 * (u - b1)', 'return s * (2.0 * a1 * (u - b1)',
             ('test/led/test_intensity_model.py', 'test/led/test_scanning_ekf.py')),
    Mutation('E5', 'three-point averaging eq. (26) with V2 - V1', 'tskf_ros/led/baselines.py',
             'gamma_p = g * (v1 - v2) / total', 'gamma_p = g * (v2 - v1) / total',
             ('test/led/test_baselines.py',), 'three_point'),
    Mutation('G1', 'session gate: d^2 compared with the gate, not its square', ADMISSION,
             'if d2 < 0.0 or d2 <= gate * gate:', 'if d2 < 0.0 or d2 <= gate:',
             ('test/owc/session/test_admission.py', 'test/owc/session/test_session.py')),
)


def check_snippets(root: Path, mutations) -> list:
    """Return the stale mutations: snippets not found exactly once under root."""
    stale = []
    for m in mutations:
        text = (root / m.path).read_text()
        count = text.count(m.original)
        if count != 1:
            stale.append(f'{m.name}: {m.path} has the snippet {count} times, not once: '
                         f'{m.original!r}')
    return stale


def make_copy() -> Path:
    """Copy the repository's sources and tests into a fresh temporary directory."""
    tmp = Path(tempfile.mkdtemp(prefix='tskf_mutation_'))
    for name in COPIED:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, tmp / name, ignore=IGNORED)
        elif src.is_file():
            shutil.copy2(src, tmp / name)
    return tmp


def environment(copy: Path) -> dict:
    """Return the environment that makes Python import the copy's tskf_ros."""
    env = dict(os.environ)
    env['PYTHONPATH'] = str(copy) + (os.pathsep + env['PYTHONPATH']
                                     if env.get('PYTHONPATH') else '')
    env['PYTHONDONTWRITEBYTECODE'] = '1'
    # one BLAS thread: the core's 2 x 2 products are ten times slower in CPU time with
    # OpenBLAS threads spinning on a busy 2-core machine
    for name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
        env.setdefault(name, '1')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
    return env


def check_imports_the_copy(copy: Path, env: dict) -> None:
    """Raise SystemExit unless python (and pytest's conftest) import tskf_ros from the copy."""
    probe = subprocess.run([sys.executable, '-c', 'import tskf_ros; print(tskf_ros.__file__)'],
                           cwd=copy, env=env, capture_output=True, text=True, timeout=60)
    where = Path(probe.stdout.strip()).resolve()
    if probe.returncode != 0 or copy.resolve() not in where.parents:
        raise SystemExit(f'the copy is not what gets imported: tskf_ros from {where} '
                         f'(stderr: {probe.stderr.strip()})')
    # the same inside pytest: a test that fails unless tskf_ros comes from the copy
    test = copy / 'test' / 'test_zz_mutation_probe.py'
    test.write_text('import tskf_ros\n\n\ndef test_probe():\n'
                    f'    assert tskf_ros.__file__.startswith({str(copy.resolve())!r})\n')
    try:
        run = run_pytest(copy, env, [str(test.relative_to(copy))], timeout=120)
    finally:
        test.unlink()
    if not run[0]:
        raise SystemExit('inside pytest, tskf_ros is not imported from the copy:\n' + run[2])
    print(f'imports tskf_ros from {where.parent} (python and pytest)')


def run_pytest(copy: Path, env: dict, args: list, timeout: float) -> tuple:
    """Run pytest -x -q in the copy; return (passed, seconds, output)."""
    start = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, '-m', 'pytest', '-x', '-q', '-p',
                               'no:cacheprovider', *args], cwd=copy, env=env,
                              capture_output=True, text=True, timeout=timeout)
        passed, out = proc.returncode == 0, proc.stdout + proc.stderr
    except subprocess.TimeoutExpired as exc:
        passed, out = False, f'timed out after {timeout} s\n{exc.stdout or ""}'
    return passed, time.perf_counter() - start, out


def first_failure(output: str) -> str:
    """Return the first FAILED/ERROR test id in pytest -q output ('' if none)."""
    for line in output.splitlines():
        if line.startswith(('FAILED ', 'ERROR ')):
            return line.split(' - ')[0]
    return ''


def main(argv=None) -> int:
    """Run the mutations; print the table and the score."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--only', nargs='+', metavar='NAME', help='run only these mutations')
    parser.add_argument('--list', action='store_true', help='list the mutations and exit')
    parser.add_argument('--keep', action='store_true', help='keep the temporary copy')
    parser.add_argument('--timeout', type=float, default=600.0, help='per run, s (600)')
    args = parser.parse_args(argv)
    mutations = [m for m in MUTATIONS if not args.only or m.name in args.only]
    if args.only and len(mutations) != len(set(args.only)):
        parser.error(f'unknown mutation in {args.only}')
    if args.list:
        for m in mutations:
            print(f'{m.name:4s} {m.path:40s} {m.what}')
        return 0
    stale = check_snippets(REPO, mutations)
    if stale:
        print('STALE MUTATIONS (the code changed; update bench/mutation_check.py):',
              *stale, sep='\n  ', file=sys.stderr)
        return 2
    copy = make_copy()
    env = environment(copy)
    rows, ok = [], True
    try:
        check_imports_the_copy(copy, env)
        baseline = {}
        for m in mutations:
            key = tuple(m.pytest_args())
            if key not in baseline:
                baseline[key] = run_pytest(copy, env, list(key), args.timeout)
                if not baseline[key][0]:
                    print(f'baseline FAILS for {" ".join(key)} (fix the tests first):\n'
                          + baseline[key][2][-3000:], file=sys.stderr)
                    return 3
        print(f'baseline: {len(baseline)} test selections pass unmutated')
        for m in mutations:
            path = copy / m.path
            original = path.read_text()
            if original.count(m.original) != 1:
                raise SystemExit(f'stale mutation {m.name} in the copy')
            path.write_text(original.replace(m.original, m.replacement))
            try:
                passed, seconds, out = run_pytest(copy, env, m.pytest_args(), args.timeout)
            finally:
                path.write_text(original)
            caught = not passed
            ok &= caught
            failure = first_failure(out)
            rows.append((m, caught, seconds, failure))
            print(f'{m.name:4s} {"caught" if caught else "SURVIVED":8s} {seconds:6.1f} s  '
                  f'{m.what}\n     {failure}', flush=True)
            if not caught:
                print('  tests run: ' + ' '.join(m.pytest_args()))
    finally:
        if args.keep:
            print(f'kept the copy in {copy}')
        else:
            shutil.rmtree(copy, ignore_errors=True)
    caught = sum(1 for row in rows if row[1])
    print('\n| mutation | file | what | caught by | seconds |\n| --- | --- | --- | --- | --- |')
    for m, c, seconds, failure in rows:
        by = failure.split('::', 1)[-1] if c else '**survived**'
        print(f'| {m.name} | `{m.path}` | {m.what} | {by} | {seconds:.1f} |')
    print(f'\nscore: {caught}/{len(rows)} caught')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
