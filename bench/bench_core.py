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
Cost of the ROS-free core against its performance goals, in one run.

    OPENBLAS_NUM_THREADS=1 python bench/bench_core.py [--repeats 7] [--quick] [--only ...]

Thread CPU time (time.thread_time_ns) per call, min / median over the repeats; the cases
of a part alternate within each repeat, so a load that comes and goes hits them alike.

1. `TimeScaleKalmanFilter.step` with a plain-float reading (Euler, one output) against
   FilterPy 2.0.0's `KalmanFilter.predict()` + `update(z)` on the same model (F = I + mu A,
   Q_d = mu GQG^T, R_d = R / mu), n = 1, 2, 3, 6, 20, 50.  Without FilterPy the reference
   is `TextbookKF` below, the same numpy calls.  Goals: n = 1, 2 <= 0.5x; n = 3 .. 50
   <= 1.0x.
2. `EstimatorSession.add` (the OWC model, 1 kHz, in order) beside the step it makes, and
   the add with kf.step answering a stored result (the session's own work); no goal.  A
   late sample (one point late) against history_size 10 .. 10 000: flat (the largest /
   the smallest <= 2).
3. One scanning-EKF step (runs = 1, as the live alignment node runs it), the alignment
   session's whole `add`, and a step of 1000 runs (the Monte-Carlo form); no goal.
4. Exact stamps and stamps jittered by +-1 % and +-5 % of the period (a new mu every
   call): `step` against FilterPy rebuilding F, Q_d, R_d each step (Euler, and the exact
   transition with the same Van Loan kernel, its series made once), n = 1, 2, 6, 20
   (goals <= 0.5x, n = 20 <= 1.0x; exact within 1.2x of Euler); `kf.run` against
   FilterPy's `batch_filter` given Fs, Qs, Rs, n = 2 (goal <= 0.2x). Results are checked
   equal; ratios of medians.
5. `rts_smooth`, K = 1e6 (`--rss-points`), n = 2, +-1 % jitter, in a fresh process: the
   peak RSS of the call (the kernel's high-water mark, reset before it) over the RSS before
   it, against the size of its output (goal <= 2x); `--rss-baseline DIR` alternates it
   with the package of another source tree (DIR/tskf_ros, e.g. `git archive` of a commit).

Figures only; nothing is asserted.
"""

import argparse
import functools
import os
import platform
import statistics
import time
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from tskf_ros import led  # noqa: E402
from tskf_ros.core.linear_models import owc  # noqa: E402
from tskf_ros.core.timescale_kalman import StepResult, TimeScaleKalmanFilter  # noqa: E402
from tskf_ros.core.units import NS  # noqa: E402
from tskf_ros.led.alignment_session import AlignmentConfig, AlignmentSession  # noqa: E402
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession  # noqa: E402

try:
    from filterpy.kalman import KalmanFilter
except ImportError:         # not installed: the textbook copy of its calls below
    KalmanFilter = None

SIZES = (1, 2, 3, 6, 20, 50)
HISTORIES = (10, 100, 1000, 10000)
MU = 0.01
T0 = 1_700_000_000 * NS


class TextbookKF:
    """FilterPy 2.0.0's KalmanFilter.predict() and update(z): the same numpy calls."""

    def __init__(self, F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray,
                 x: np.ndarray, P: np.ndarray) -> None:
        self.F, self.Q, self.H, self.R, self.x, self.P = F, Q, H, R, x, P
        self._I = np.eye(len(x))

    def predict(self) -> None:
        """Predict: x = F x, P = F P F^T + Q, and keep the prior."""
        F = self.F
        self.x = np.dot(F, self.x)
        self.P = 1.0 * np.dot(np.dot(F, self.P), F.T) + self.Q
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def update(self, z: np.ndarray) -> None:
        """Update in Joseph form, and keep the posterior."""
        H, R = self.H, self.R
        z = np.atleast_2d(z)[0] if np.ndim(z) > 1 else np.asarray(z)
        self.y = z - np.dot(H, self.x)
        PHT = np.dot(self.P, H.T)
        self.S = np.dot(H, PHT) + R
        self.SI = np.linalg.inv(self.S)
        self.K = np.dot(PHT, self.SI)
        self.x = self.x + np.dot(self.K, self.y)
        I_KH = self._I - np.dot(self.K, H)
        self.P = np.dot(np.dot(I_KH, self.P), I_KH.T) + np.dot(np.dot(self.K, R), self.K.T)
        self.z = z.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()


def per_call(fn, calls: int) -> float:
    """Thread CPU time per call of fn, in us."""
    start = time.thread_time_ns()
    for _ in range(calls):
        fn()
    return (time.thread_time_ns() - start) / calls / 1e3


def alternate(cases: dict, calls: dict, repeats: int) -> dict:
    """Run every case once per repeat, in turn; return name -> list of us per call."""
    out = {name: [] for name in cases}
    for _ in range(repeats):
        for name, fn in cases.items():
            out[name].append(per_call(fn, calls[name]))
    return out


def mm(values: list) -> str:
    """Return 'min / median' of values (us)."""
    return f'{min(values):8.2f} / {statistics.median(values):8.2f}'


def verdict(ok: bool) -> str:
    """Return MET or NOT MET."""
    return 'MET' if ok else 'NOT MET'


def random_model(rng: np.random.Generator, n: int) -> dict:
    """Return a stable random model with one output and SPD covariances."""
    M = rng.normal(size=(n, n))
    return {'A': rng.normal(size=(n, n)) * 0.3 / np.sqrt(n) - np.eye(n),
            'C': rng.normal(size=(1, n)), 'Q': np.eye(n) * 0.1, 'R': [[2.0]],
            'x0': rng.normal(size=n), 'P0': M @ M.T + np.eye(n)}


def goal_step(repeats: int, quick: bool) -> None:
    """Goal 1: the step against FilterPy at every size."""
    reference = 'FilterPy ' + __import__('filterpy').__version__ if KalmanFilter else (
        'TextbookKF (FilterPy not installed)')
    print(f'\n1. TimeScaleKalmanFilter.step vs {reference} predict+update, '
          f'Euler, p = 1, mu = {MU}')
    print('    n   step min / median (us)   reference min / median (us)   ratio   goal')
    rng = np.random.default_rng(0)
    limits = {1: 0.5, 2: 0.5}
    for n in SIZES:
        m = random_model(rng, n)
        kf = TimeScaleKalmanFilter(**m)
        F = np.eye(n) + MU * m['A']
        if KalmanFilter is not None:
            ref = KalmanFilter(dim_x=n, dim_z=1)
            ref.F, ref.Q, ref.H = F, MU * m['Q'], m['C']
            ref.R, ref.x, ref.P = np.array(m['R']) / MU, m['x0'].copy(), m['P0'].copy()
        else:
            ref = TextbookKF(F, MU * m['Q'], m['C'], np.array(m['R']) / MU, m['x0'].copy(),
                             m['P0'].copy())
        y = 0.5                 # plain-float input, as a node passes a reading
        z = np.array([0.5])

        def ours(kf=kf, y=y) -> None:
            kf.step(MU, y)

        def theirs(ref=ref, z=z) -> None:
            ref.predict()
            ref.update(z)

        calls = max(200, 20000 // (n * n)) // (10 if quick else 1)
        got = alternate({'step': ours, 'ref': theirs}, {'step': calls, 'ref': calls}, repeats)
        ratio = min(got['step']) / min(got['ref'])
        limit = limits.get(n, 1.0)
        print(f'  {n:3d}   {mm(got["step"])}        {mm(got["ref"])}            '
              f'{ratio:5.2f}   <= {limit:.2f}x {verdict(ratio <= limit)}')


def owc_session(history: int = 1000) -> EstimatorSession:
    """Return the OWC estimator at 1 kHz with the given history."""
    return EstimatorSession(EstimatorConfig(owc(), period=0.001, history_size=history,
                                            history_window=1e6, max_backward=1e6))


def goal_session(repeats: int, quick: bool) -> None:
    """Goal 2: session.add against the step; a late sample against history_size."""
    model = owc()
    y = float(model.C[0] @ model.x0 + model.D[0])
    session = owc_session()
    kf = model.make_filter()
    stamp = [T0]

    def add() -> None:
        stamp[0] += 1_000_000
        session.add(stamp[0], y)

    def step() -> None:
        kf.step(0.001, y)       # a plain-float reading, as the node passes it to add

    # what the session adds: the same add with kf.step answering one stored result (and
    # moving x, P to it, as a step does)
    replay = owc_session()
    replay.add(T0, y)
    stored = replay.kf.step(0.001, y)
    replay.kf.x, replay.kf.P = model.x0.copy(), model.P0.copy()

    def replayed(mu: float, y: ArrayLike, u: Optional[ArrayLike] = None, *,
                 R: Optional[ArrayLike] = None) -> StepResult:
        replay.kf.x, replay.kf.P = stored.x_predicted, stored.P_predicted
        return stored

    replay.kf.step = replayed
    replay_stamp = [T0]

    def add_without_step() -> None:
        replay_stamp[0] += 1_000_000
        replay.add(replay_stamp[0], y)

    calls = 2000 // (10 if quick else 1)
    got = alternate({'add': add, 'step': step, 'rest': add_without_step},
                    {'add': calls, 'step': calls, 'rest': calls}, repeats)
    ratio = min(got['add']) / min(got['step'])
    print('\n2. EstimatorSession.add (OWC, n = 1, in order) vs the step of the same filter')
    print(f'   session.add {mm(got["add"])} us   step {mm(got["step"])} us   '
          f'ratio {ratio:.2f}')
    print('   session.add with kf.step answering a stored result (the work of the session '
          f'alone: checks, gate, history, statistics, outcome): {mm(got["rest"])} us')

    print('   a sample one point late (insert + re-run of 2 steps) vs history_size')
    sessions, clocks = {}, {}
    for h in HISTORIES:
        s = owc_session(h)
        t = T0
        for _ in range(h + 5):
            t += 1_000_000
            s.add(t, y)
        sessions[h], clocks[h] = s, [t]
    late = {h: [] for h in HISTORIES}
    per_repeat = 200 // (10 if quick else 1)
    for _ in range(repeats):
        for h in HISTORIES:
            s, c, total = sessions[h], clocks[h], 0
            for _ in range(per_repeat):
                c[0] += 2_000_000
                s.add(c[0], y)                      # the newest point (not timed)
                start = time.thread_time_ns()
                out = s.add(c[0] - 1_000_000, y)    # late: between the last two points
                total += time.thread_time_ns() - start
                assert out.status == 'inserted', out
            late[h].append(total / per_repeat / 1e3)
    for h in HISTORIES:
        print(f'   history {h:6d}: {mm(late[h])} us per late sample')
    flat = min(late[HISTORIES[-1]]) / min(late[HISTORIES[0]])
    print(f'   history {HISTORIES[-1]} / {HISTORIES[0]}: {flat:.2f}   flat (<= 2) '
          f'{verdict(flat <= 2.0)}')


def goal_alignment(repeats: int, quick: bool) -> None:
    """One scanning-EKF step (runs = 1, as the live node) and the alignment session's add."""
    one = led.ScanningEKF(runs=1)
    batch = led.ScanningEKF(runs=1000)
    session = AlignmentSession(AlignmentConfig())
    clock = {'one': [0.0], 'batch': [0.0], 'add': [T0]}
    z = np.ones(1000)

    def step_one() -> None:
        clock['one'][0] += 0.05
        one.step(clock['one'][0], 1.0)

    def step_batch() -> None:
        clock['batch'][0] += 0.05
        batch.step(clock['batch'][0], z)

    def add() -> None:
        clock['add'][0] += 50_000_000
        session.add(clock['add'][0], 1.0)

    calls = 2000 // (10 if quick else 1)
    got = alternate({'one': step_one, 'batch': step_batch, 'add': add},
                    {'one': calls, 'batch': max(1, calls // 100), 'add': calls}, repeats)
    print('\n3. Scanning EKF (Solanki et al.)')
    print(f'   ScanningEKF.step, runs = 1 (the live node)  {mm(got["one"])} us')
    print(f'   AlignmentSession.add (gate + step + checks) {mm(got["add"])} us')
    print(f'   ScanningEKF.step, runs = 1000 (Monte Carlo)  {mm(got["batch"])} us   '
          f'{min(got["batch"]) / 1000:.2f} us per run')


JITTERS = (0.0, 0.01, 0.05)         # stamp jitter, +- a fraction of the period


def jittered(rng: np.random.Generator, K: int, jitter: float) -> np.ndarray:
    """Return K graininesses MU (1 +- jitter), uniform; exact stamps for jitter 0."""
    return MU * (1.0 + rng.uniform(-jitter, jitter, K)) if jitter else np.full(K, MU)


def goal_jitter(repeats: int, quick: bool) -> None:
    """Step with a new mu per call, and kf.run, on exact and jittered stamps vs FilterPy."""
    from tskf_ros.core.transitions import van_loan_from, van_loan_series
    print('\n4. Exact and jittered stamps (+-1 %, +-5 % of the period): a new mu every call')
    print('   step vs FilterPy predict+update rebuilding F, Q_d, R_d each step '
          '(Euler: I + mu A; exact: the same Van Loan kernel, series made once); '
          'ratio of medians')
    print('   jitter  transition    n   step (us)   FilterPy (us)   ratio   goal')
    rng = np.random.default_rng(1)
    calls = 2000 // (10 if quick else 1)
    for jitter in JITTERS:
        for n in (1, 2, 6, 20):
            m = random_model(rng, n)
            mus = jittered(rng, calls, jitter)
            A, GQGt, R = m['A'], m['Q'], np.array(m['R'])
            # the model's Taylor coefficients of F and Q_d, made once as the filter does
            series = van_loan_series(A, GQGt)
            got, cases, state = {}, {}, {}
            for kind in ('euler', 'exact'):
                kf = TimeScaleKalmanFilter(**m, transition=kind)
                ref = KalmanFilter(dim_x=n, dim_z=1)
                ref.H, ref.x, ref.P = m['C'], m['x0'].copy(), m['P0'].copy()
                state[kind] = (kf, ref)

                def ours(kf=kf, mus=mus) -> None:
                    for mu in mus.tolist():
                        kf.step(mu, 0.5)

                def theirs(ref=ref, mus=mus, kind=kind, series=series) -> None:
                    z = np.array([0.5])
                    for mu in mus.tolist():
                        # the step's order: the update at t (R_d = R / mu), then the
                        # prediction over mu
                        ref.R = R / mu
                        ref.update(z)
                        if kind == 'euler':
                            ref.F, ref.Q = np.eye(n) + mu * A, mu * GQGt
                        else:
                            ref.F, ref.Q = van_loan_from(*series, mu)
                        ref.predict()
                cases[kind], cases[kind + ' ref'] = ours, theirs
            got = alternate(cases, dict.fromkeys(cases, 1), repeats)
            for kind in ('euler', 'exact'):
                kf, ref = state[kind]
                # the same filter, the same steps: the same prediction
                assert np.allclose(kf.x, ref.x, rtol=1e-6, atol=1e-9), (kind, n)
                ours_us = statistics.median(got[kind]) / calls
                ref_us = statistics.median(got[kind + ' ref']) / calls
                limit = 1.0 if n == 20 else 0.5
                print(f'   {jitter:5.0%}   {kind:10s}  {n:3d}   {ours_us:9.2f}   {ref_us:13.2f}   '
                      f'{ours_us / ref_us:5.2f}   <= {limit:.1f}x '
                      f'{verdict(ours_us <= limit * ref_us)}')
            e, x = statistics.median(got['euler']), statistics.median(got['exact'])
            print(f'   {jitter:5.0%}   exact / euler {n:3d}   {x / e:5.2f}   <= 1.2x '
                  f'{verdict(x <= 1.2 * e)}')

    print('\n   kf.run vs FilterPy batch_filter (given Fs, Qs, Rs), n = 2, K = 2000, '
          'the same model and measurements; ratio of medians')
    print('   jitter  transition   run (us/step)   batch_filter (us/step)   ratio   goal')
    K = 2000 // (10 if quick else 1)
    m = random_model(rng, 2)
    zs = rng.normal(size=(K, 1))
    for jitter in JITTERS:
        mus = jittered(rng, K, jitter)
        for kind in ('euler', 'exact'):
            kf = TimeScaleKalmanFilter(**m, transition=kind)
            jumps = kf.transition_stack(mus)
            Rs = np.array(m['R'])[None] / mus[:, None, None]
            out = {}

            def ours(kf=kf, mus=mus) -> None:
                kf.x, kf.P = m['x0'].copy(), m['P0'].copy()
                out['run'] = kf.run(mus, zs)

            def theirs(jumps=jumps, Rs=Rs) -> None:
                ref = KalmanFilter(dim_x=2, dim_z=1)
                ref.H, ref.x, ref.P = m['C'], m['x0'].copy(), m['P0'].copy()
                ref.F, ref.Q, ref.R = jumps.F[0], jumps.Qd[0], Rs[0]
                # batch_filter updates then predicts: its (means, covariances) are our
                # corrected rows
                out['ref'] = ref.batch_filter(zs, Fs=jumps.F, Qs=jumps.Qd, Hs=[m['C']] * K,
                                              Rs=Rs, update_first=True)

            got = alternate({'run': ours, 'ref': theirs}, {'run': 1, 'ref': 1}, repeats)
            np.testing.assert_allclose(out['run'].x_corrected, out['ref'][0], rtol=1e-8,
                                       atol=1e-10)
            r, f = statistics.median(got['run']) / K, statistics.median(got['ref']) / K
            print(f'   {jitter:5.0%}   {kind:10s}   {r:13.2f}   {f:22.2f}   {r / f:5.2f}   '
                  f'<= 0.2x {verdict(r <= 0.2 * f)}')


RSS_SCRIPT = """
import resource, sys, time
if len(sys.argv) > 2:       # an older source tree of the package, to compare
    sys.path.insert(0, sys.argv[2])
import numpy as np
from tskf_ros.core import rts_smooth


def hwm():
    # the kernel's high-water mark of this process (kB), and its resident set now
    with open('/proc/self/status') as f:
        rows = dict(line.split(':', 1) for line in f)
    return int(rows['VmHWM'].split()[0]), int(rows['VmRSS'].split()[0])


K = int(sys.argv[1])
rng = np.random.default_rng(0)
mu = 0.01 * (1 + rng.uniform(-0.01, 0.01, K))
y = rng.normal(size=(K, 1))
kw = dict(Q=np.eye(2) * 0.1, R=[[0.5]], x0=[0.0, 0.0], P0=np.eye(2))
A, C = [[0.0, 1.0], [-1.0, -0.3]], [[1.0, 0.0]]
rts_smooth(A, C, mu[:10], y[:10], **kw)
try:        # start the high-water mark afresh (Linux: clear_refs 5)
    with open('/proc/self/clear_refs', 'w') as f:
        f.write('5')
    before = hwm()[1]
    t0 = time.thread_time()
    out = rts_smooth(A, C, mu, y, **kw)
    cpu = time.thread_time() - t0
    after = hwm()[0]
except OSError:
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.thread_time()
    out = rts_smooth(A, C, mu, y, **kw)
    cpu = time.thread_time() - t0
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(before, after, out.xs.nbytes + out.Ps.nbytes, cpu)
"""


def goal_rss(repeats: int, quick: bool, points: Optional[int] = None,
             baseline: Optional[str] = None) -> None:
    """Peak RSS of rts_smooth, K = 1e6, n = 2, +-1 % jitter, in a fresh process."""
    import subprocess
    import sys
    K = points or (100_000 if quick else 1_000_000)
    trees: dict[str, list[tuple[float, float]]] = {'this tree': []}
    if baseline is not None:
        trees[baseline] = []
    print(f'\n5. rts_smooth, K = {K}, n = 2, +-1 % jitter (a fresh process each, the peak RSS '
          'of the call over the RSS before it)')
    for _ in range(3 if baseline else 1):
        for tree in trees:
            extra = [] if tree == 'this tree' else [tree]
            out = subprocess.run([sys.executable, '-c', RSS_SCRIPT, str(K)] + extra, check=True,
                                 capture_output=True, text=True).stdout.split()
            before, after, size = int(out[0]) * 1024, int(out[1]) * 1024, int(out[2])
            grew, cpu = after - before, float(out[3])
            print(f'   {tree}: peak RSS {after / 2**20:.0f} MB, {before / 2**20:.0f} MB before '
                  f'the call: grew {grew / 2**20:.0f} MB for an output of {size / 2**20:.0f} MB: '
                  f'{grew / size:.2f}x   <= 2x {verdict(grew <= 2 * size)}; the call '
                  f'{cpu:.2f} s thread CPU')
            trees[tree].append((grew / size, cpu))
    if baseline is not None:
        ours, theirs = trees['this tree'], trees[baseline]
        cpu_ratio = (statistics.median(c for _, c in ours)
                     / statistics.median(c for _, c in theirs))
        print(f'   medians, this tree / {baseline}: RSS growth over output '
              f'{statistics.median(g for g, _ in ours):.2f}x / '
              f'{statistics.median(g for g, _ in theirs):.2f}x, CPU of the call '
              f'{cpu_ratio:.2f}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--repeats', type=int, default=7, help='repeats (>= 5)')
    parser.add_argument('--quick', action='store_true', help='a tenth of the calls')
    parser.add_argument('--rss-points', type=int, help='K of part 5 (default 1e6)')
    parser.add_argument('--rss-baseline', metavar='DIR',
                        help='part 5 alternated with the package in DIR (DIR/tskf_ros)')
    parser.add_argument('--only', nargs='+',
                        choices=('step', 'session', 'alignment', 'jitter', 'rss'),
                        help='run only these parts')
    args = parser.parse_args()
    load = os.getloadavg()
    print(f'{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, '
          f'numpy {np.__version__}, OPENBLAS_NUM_THREADS='
          f'{os.environ.get("OPENBLAS_NUM_THREADS", "unset")}, load average '
          f'{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}')
    print(f'thread CPU time per call, min / median over {args.repeats} repeats, '
          'cases alternated')
    parts = {'step': goal_step, 'session': goal_session, 'alignment': goal_alignment,
             'jitter': goal_jitter,
             'rss': functools.partial(goal_rss, points=args.rss_points,
                                      baseline=args.rss_baseline)}
    for name in args.only or list(parts):
        parts[name](args.repeats, args.quick)


if __name__ == '__main__':
    main()
