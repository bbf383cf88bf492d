"""
Cost of the ROS-free core against its goals (issue 13, goals 1, 2 and 5), in one run.

    OPENBLAS_NUM_THREADS=1 python bench/bench_core.py [--repeats 7] [--quick]

Thread CPU time (time.thread_time_ns) per call, min / median over the repeats; the cases
of a goal alternate within each repeat, so a load that comes and goes hits them alike.

1. `TimeScaleKalmanFilter.step` (Euler, one output, a measurement every step) against
   FilterPy's `KalmanFilter.predict()` + `update(z)` on the same model (F = I + mu A,
   Q_d = mu GQG^T, R_d = R / mu), n = 1, 2, 3, 6, 20, 50.  FilterPy is pinned in
   requirements.txt for this script only; without it the reference is `TextbookKF`
   below, the same numpy calls as FilterPy 2.0.0's predict and update.  Goals: n = 1
   <= 0.25x, n = 2 <= 0.5x, n <= 6 <= 1.0x, n = 20, 50 <= 1.0x.
2. `EstimatorSession.add` (the OWC model, 1 kHz, in order) against the step of the same
   filter: <= 1.5x.  The add makes that step (`kf.step`, the session's one path); the add
   with kf.step answering a stored result is printed too (the session's own work: checks,
   gate, history, statistics, outcome).  A late sample (one point late) against
   history_size 10 .. 10 000: flat (the largest / the smallest <= 2).
3. One scanning-EKF step (runs = 1, as the live alignment node runs it) and the alignment
   session's whole `add` (gate, step, checks): <= 50 us.  The vectorised form, which the
   Monte-Carlo experiments use, is printed beside it.

Figures only; nothing is asserted.
"""

import argparse
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
          f'ratio {ratio:.2f}   <= 1.50x {verdict(ratio <= 1.5)}')
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
    print(f'   ScanningEKF.step, runs = 1 (the live node)  {mm(got["one"])} us   '
          f'<= 50 us {verdict(min(got["one"]) <= 50)}')
    print(f'   AlignmentSession.add (gate + step + checks) {mm(got["add"])} us   '
          f'<= 50 us {verdict(min(got["add"]) <= 50)}')
    print(f'   ScanningEKF.step, runs = 1000 (Monte Carlo)  {mm(got["batch"])} us   '
          f'{min(got["batch"]) / 1000:.2f} us per run')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--repeats', type=int, default=7, help='repeats (>= 5)')
    parser.add_argument('--quick', action='store_true', help='a tenth of the calls')
    parser.add_argument('--only', nargs='+', choices=('step', 'session', 'alignment'),
                        help='run only these parts')
    args = parser.parse_args()
    load = os.getloadavg()
    print(f'{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, '
          f'numpy {np.__version__}, OPENBLAS_NUM_THREADS='
          f'{os.environ.get("OPENBLAS_NUM_THREADS", "unset")}, load average '
          f'{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}')
    print(f'thread CPU time per call, min / median over {args.repeats} repeats, '
          'cases alternated')
    parts = {'step': goal_step, 'session': goal_session, 'alignment': goal_alignment}
    for name in args.only or list(parts):
        parts[name](args.repeats, args.quick)


if __name__ == '__main__':
    main()
