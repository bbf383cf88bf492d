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
Time and memory of the alignment Monte Carlo against its goals, in one run.

    python bench/bench_monte_carlo.py [--repeats 3] [--quick] [--against DIR]

1. The default comparison (`python -m tskf_ros.experiments.alignment_mc --runs 1000`:
   7 algorithms x 11 noise levels) on every core and on one (--workers 1), alternated,
   wall time median over the repeats.  Goal: <= 5 s on every core.
2. One algorithm (ekf_pat) at one level (1 V) for 1e3, 1e4 and 1e5 runs on every core:
   wall time and peak RSS.  Goals: 1e5 runs in <= 60 s; RSS flat in the number of runs.

--against DIR: a source tree of another commit (`git worktree add DIR COMMIT`, or
`git archive COMMIT tskf_ros | tar -x -C DIR`), whose tskf_ros is put first on
PYTHONPATH: its default comparison on every core is alternated with this tree's, and its
1e3..1e5 runs follow this tree's, for a before / after ratio measured in the same run.

    python bench/bench_monte_carlo.py --lqg [--repeats 3] [--against DIR]

3. (--lqg, instead of 1 and 2) `lqg_comparison` (3 controllers x 10 points of 1000 runs),
   on every core and on one, alternated (and DIR's on every core); then its two points
   at --betas 14 (6 points) at 1e3 and 1e4 runs: peak RSS, which should be flat.

Each command runs in a fresh process; RSS is sampled every 0.1 s over the process and its
workers: the peak of their sum, and of the largest.  The load average is printed beside
each figure: the machine may be shared, so the CPU time of the process and its workers is
printed too (on idle cores the wall time is about CPU / workers, plus the start-up).
Figures only; nothing is asserted.
"""

import argparse
from dataclasses import dataclass
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Optional

MODULE = 'tskf_ros.experiments.alignment_mc'
LQG_MODULE = 'tskf_ros.experiments.lqg_comparison'
GOAL_DEFAULT_S = 5.0
GOAL_1E5_S = 60.0


PAGE = os.sysconf('SC_PAGE_SIZE')


def tree_rss(root: int) -> list[int]:
    """Return the RSS (bytes) of process root and of its descendants, from /proc (Linux)."""
    parent: dict[int, int] = {}
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                with open(f'/proc/{entry}/stat') as f:
                    # pid (comm) state ppid ...: comm may hold spaces, so split after ')'
                    parent[int(entry)] = int(f.read().rsplit(')', 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue            # the process ended meanwhile
    tree, grew = {root}, True
    while grew:
        more = {pid for pid, ppid in parent.items() if ppid in tree} - tree
        tree |= more
        grew = bool(more)
    rss = []
    for pid in tree:
        try:
            with open(f'/proc/{pid}/statm') as f:
                rss.append(int(f.read().split()[1]) * PAGE)
        except (OSError, ValueError, IndexError):
            continue
    return rss


@dataclass
class Measured:
    """One command: wall and CPU time (s), peak RSS of the process tree's sum and largest."""

    wall_s: float
    cpu_s: float
    peak_sum_mb: float
    peak_one_mb: float
    load: float


def measure(args: list[str], tree: Optional[str] = None, module: str = MODULE) -> Measured:
    """Run `python -m module args` (tree's, if given) in a fresh process; sample RSS."""
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = dict(os.environ)
    if tree is not None:
        env['PYTHONPATH'] = os.pathsep.join([tree, *filter(None, [env.get('PYTHONPATH')])])
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, '-m', module, *args], cwd=tmp, env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        peak_sum = peak_one = 0
        while proc.poll() is None:
            rss = tree_rss(proc.pid)
            if rss:
                peak_sum, peak_one = max(peak_sum, sum(rss)), max(peak_one, max(rss))
            time.sleep(0.1)
        wall = time.perf_counter() - start
        err = proc.stderr.read().decode() if proc.stderr else ''
        if proc.returncode:
            raise SystemExit(f'{module} {" ".join(args)} failed:\n{err}')
    # the CPU time of the process and of the workers it waited for
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return Measured(wall, cpu, peak_sum / 2**20, peak_one / 2**20, load)


def verdict(ok: bool) -> str:
    """Return MET or NOT MET."""
    return 'MET' if ok else 'NOT MET'


def summary(runs: list[Measured]) -> str:
    """Median wall time, the runs' wall times and loads, CPU and peak RSS of a figure."""
    wall = statistics.median(m.wall_s for m in runs)
    return (f'{wall:6.1f} s median of {", ".join(f"{m.wall_s:.1f}" for m in runs)} s (load '
            f'{", ".join(f"{m.load:.1f}" for m in runs)}), CPU '
            f'{statistics.median(m.cpu_s for m in runs):.1f} s; peak RSS '
            f'{max(m.peak_sum_mb for m in runs):.0f} MB in all, '
            f'{max(m.peak_one_mb for m in runs):.0f} MB the largest process')


def main() -> None:
    """Measure and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--repeats', type=int, default=3, help='repeats of part 1 (3)')
    parser.add_argument('--quick', action='store_true',
                        help='part 1 once, part 2 up to 1e4 runs')
    parser.add_argument('--against', metavar='DIR',
                        help="another commit's source tree, measured alongside (before / after)")
    parser.add_argument('--lqg', action='store_true',
                        help='measure lqg_comparison (part 3) instead of alignment_mc')
    args = parser.parse_args()
    if args.against and not os.path.isdir(os.path.join(args.against, 'tskf_ros')):
        raise SystemExit(f'--against {args.against}: no tskf_ros package in it')
    cores = os.cpu_count() or 1
    print(f'{platform.machine()}, {cores} CPUs, Python {platform.python_version()}; '
          'load average (1 min) beside each figure')

    if args.lqg:
        lqg(args, cores)
        return
    print(f'\n1. the default comparison, --runs 1000 (7 algorithms x 11 levels): '
          f'--workers {cores} vs --workers 1, alternated'
          + (f'; and {args.against} on --workers {cores}' if args.against else ''))
    cases = [('this tree', cores, None), ('this tree', 1, None)]
    if args.against:
        cases.append((args.against, cores, args.against))
    got: dict[tuple, list[Measured]] = {case: [] for case in cases}
    for _ in range(1 if args.quick else args.repeats):
        for case in cases:
            got[case].append(measure(['--runs', '1000', '--workers', str(case[1])], case[2]))
    for (name, workers, tree), runs in got.items():
        wall = statistics.median(m.wall_s for m in runs)
        goal = (f'   <= {GOAL_DEFAULT_S:g} s {verdict(wall <= GOAL_DEFAULT_S)}'
                if workers == cores and tree is None else '')
        print(f'   {name}, --workers {workers}: {summary(runs)}{goal}')
    one, many = (statistics.median(m.wall_s for m in got[('this tree', w, None)])
                 for w in (1, cores))
    print(f'   speed-up on {cores} workers: {one / many:.2f}x')
    if args.against:
        before = got[(args.against, cores, args.against)]
        now = got[('this tree', cores, None)]
        wall, cpu = median_ratios(now, before)
        print(f'   this tree / {args.against}, --workers {cores}: wall {wall:.2f}, '
              f'CPU {cpu:.2f}')

    print(f'\n2. ekf_pat at 1 V, --workers {cores}: time and peak RSS against the runs')
    print('   tree         runs    wall (s)   CPU (s)   RSS all (MB)   RSS largest (MB)   load'
          '   goal')
    trees = [('this tree', None)] + ([(args.against, args.against)] if args.against else [])
    for runs in (1000, 10000) if args.quick else (1000, 10000, 100000):
        for name, tree in trees:
            m = measure(['--runs', str(runs), '--noise-levels', '1', '--algorithms', 'ekf_pat',
                         '--workers', str(cores)], tree)
            goal = (f'<= {GOAL_1E5_S:g} s {verdict(m.wall_s <= GOAL_1E5_S)}'
                    if runs == 100000 and tree is None else '')
            print(f'   {name[-10:]:>10} {runs:7d}   {m.wall_s:8.1f}   {m.cpu_s:7.1f}   '
                  f'{m.peak_sum_mb:12.0f}   {m.peak_one_mb:16.0f}   {m.load:4.1f}   {goal}',
                  flush=True)


def median_ratios(now: list[Measured], before: list[Measured]) -> tuple[float, float]:
    """Return the medians' ratios now / before of the wall time and of the CPU time."""
    wall, cpu = (statistics.median(getattr(m, key) for m in now)
                 / statistics.median(getattr(m, key) for m in before)
                 for key in ('wall_s', 'cpu_s'))
    return wall, cpu


def lqg(args: argparse.Namespace, cores: int) -> None:
    """Part 3: lqg_comparison's default on every core and one; its RSS against the runs."""
    print(f'\n3. lqg_comparison --runs 1000 (3 controllers x 10 points): --workers {cores} vs '
          '--workers 1, alternated' + (f'; and {args.against}' if args.against else ''))
    cases = [('this tree', cores, None), ('this tree', 1, None)]
    if args.against:
        cases += [(args.against, cores, args.against), (args.against, 1, args.against)]
    got: dict[tuple, list[Measured]] = {case: [] for case in cases}
    for _ in range(1 if args.quick else args.repeats):
        for case in cases:
            got[case].append(measure(['--runs', '1000', '--workers', str(case[1])], case[2],
                                     LQG_MODULE))
    for (name, workers, tree), runs in got.items():
        print(f'   {name}, --workers {workers}: {summary(runs)}')
    if args.against:
        for w in (cores, 1):
            now, before = got[('this tree', w, None)], got[(args.against, w, args.against)]
            wall, cpu = median_ratios(now, before)
            print(f'   this tree / {args.against}, --workers {w}: wall {wall:.2f}, '
                  f'CPU {cpu:.2f}')
    print(f'\n   --betas 14 (6 points), --workers {cores}: time and peak RSS against the runs')
    print('   tree         runs    wall (s)   CPU (s)   RSS all (MB)   RSS largest (MB)   load')
    trees = [('this tree', None)] + ([(args.against, args.against)] if args.against else [])
    for runs in (1000, 10000):
        for name, tree in trees:
            m = measure(['--runs', str(runs), '--betas', '14', '--workers', str(cores)], tree,
                        LQG_MODULE)
            print(f'   {name[-10:]:>10} {runs:7d}   {m.wall_s:8.1f}   {m.cpu_s:7.1f}   '
                  f'{m.peak_sum_mb:12.0f}   {m.peak_one_mb:16.0f}   {m.load:4.1f}', flush=True)


if __name__ == '__main__':
    main()
