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
Wall time of a sweep over N copies of a sample bag on 1, then 2 LocalCluster workers.

    python bench/bench_sweep.py                      # 8 copies of bags/owc_cai_td_1hz
    python bench/bench_sweep.py --copies 8 --bag bags/owc_ge_1khz --no-fit

Two workloads, each measured in this process without Dask (--workers 0), then on a
LocalCluster of 1 and of 2 worker processes, alternated, --repeats times (minimum); the times
include starting and stopping the cluster, as a user sees them.  'evaluate' runs the
estimator over each bag (light for the 1 Hz bag: Dask's overhead shows); 'evaluate + fit'
also fits Q and R (fit_noise) to each bag (a few seconds of CPU per task).  Prints the
times and the ratio 1 worker / 2 workers (2.0 would be perfect on 2 free cores).
"""

import argparse
import os
from pathlib import Path
import shutil
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tskf_ros.experiments import sweep  # noqa: E402


def timed(bags: list, out: Path, workers: int, fit: bool) -> float:
    """Run one sweep into a new table; return its wall time (s)."""
    t0 = time.perf_counter()
    res = sweep.sweep(bags, out=out, params_file=REPO / 'config' / 'owc_estimator.yaml',
                      workers=workers, fit=fit, resume=False)
    dt = time.perf_counter() - t0
    assert len(res.evaluated) == len(bags) and res.errors == 0, res
    return dt


def main() -> None:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--bag', type=Path, default=REPO / 'bags' / 'owc_cai_td_1hz')
    parser.add_argument('--copies', type=int, default=8)
    parser.add_argument('--no-fit', action='store_true', help='only the evaluate workload')
    parser.add_argument('--repeats', type=int, default=3,
                        help='runs of each case, alternated; the minimum is printed')
    args = parser.parse_args()
    os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
    print(f'{args.copies} copies of {args.bag}; {os.cpu_count()} CPUs; minimum of '
          f'{args.repeats} alternated runs')
    with tempfile.TemporaryDirectory() as tmp:
        bags = []
        for i in range(args.copies):
            shutil.copytree(args.bag, Path(tmp) / f'copy{i}')
            bags.append(str(Path(tmp) / f'copy{i}'))
        workloads = [('evaluate', False)] + ([] if args.no_fit else [('evaluate + fit', True)])
        print(f'{"workload":<16} {"in-process":>11} {"1 worker":>9} {"2 workers":>10} '
              f'{"1 / 2 workers":>14}')
        for name, fit in workloads:
            t: dict = {0: [], 1: [], 2: []}
            for _ in range(args.repeats):       # alternate the cases; keep the minimum
                for w in t:
                    t[w].append(timed(bags, Path(tmp) / f'{name}-{w}.csv', w, fit))
            best = {w: min(v) for w, v in t.items()}
            print(f'{name:<16} {best[0]:>10.2f}s {best[1]:>8.2f}s {best[2]:>9.2f}s '
                  f'{best[1] / best[2]:>14.2f}', flush=True)


if __name__ == '__main__':
    main()
