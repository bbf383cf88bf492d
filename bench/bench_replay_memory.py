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
Peak resident memory of replay_offline against the bag's length, beside a streaming rosbags read.

    python bench/bench_replay_memory.py                        # 1e5, 1e6 and 1e7 messages
    python bench/bench_replay_memory.py --sizes 100000 1000000 --work /tmp/replay_memory

For each size N, a bag of N Illuminance messages at 1 kHz (stamps jittered by +-1 % of the
period, log times 200 us later) is written once into --work (streaming: a 1e7 bag is about
1 GB and takes minutes; it is kept for the next run), then each case runs in its own
process and its peak RSS (ru_maxrss of os.wait4, the kernel's high-water mark) is printed:

- rosbags read: rosbags' Reader over every message, each deserialized and dropped (the
  reference: what reading the bag costs at all);
- replay --npz: `replay_offline BAG --npz OUT` (the arrays streamed into the .npz);
- replay -> bag: `replay_offline BAG OUT` (the output bag written as it goes);
- npz-smooth, bag-smooth: the same with --smooth (the RTS estimates at the end); beside
  them the smoothed output's size in memory (stamp, x, P, segment: 8 (2 + n + n^2) bytes
  a point) and the growth over the case without --smooth, in units of it;
- fit_noise: `tskf_fit_noise BAG --json OUT` (Q and R fitted by maximum likelihood);
- sweep: `tskf_sweep --bags BAG --workers 0 --out OUT` (one row, in this process).

--against DIR runs every case a second time with DIR (another commit's source tree, its
`tskf_ros` and `config`) first on PYTHONPATH, for a before / after in the same run.

The outputs are deleted after each case (a 1e7 output bag is several GB).  Also printed:
each case's wall time, the output's size, and the load average.
"""

import argparse
import os
from pathlib import Path
import shutil
import struct
import subprocess
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parent.parent
NS = 1_000_000_000
T0 = 1_700_000_000 * NS
PERIOD_NS = 1_000_000           # 1 kHz
PARAMS = """/**:
  ros__parameters:
    period: 0.001
"""
READ = """
import sys
from rosbags.rosbag2 import Reader
from rosbags.typesys import get_typestore, Stores
store = get_typestore(Stores.ROS2_JAZZY)
count = 0
with Reader(sys.argv[1]) as reader:
    for conn, t, data in reader.messages():
        store.deserialize_cdr(data, conn.msgtype)
        count += 1
print(count)
"""


def illuminance_cdr(stamp_ns: int, value: float, variance: float) -> bytes:
    """Return the CDR of a sensor_msgs/msg/Illuminance (frame 'power_meter')."""
    sec, nsec = divmod(stamp_ns, NS)
    frame = b'power_meter\0'
    head = struct.pack('<4siII', b'\0\1\0\0', sec, nsec, len(frame)) + frame
    pad = -(len(head) - 4) % 8
    return head + b'\0' * pad + struct.pack('<dd', value, variance)


def make_bag(path: Path, n: int, seed: int = 0, jitter_ns: int = PERIOD_NS // 100) -> None:
    """Write n messages at 1 kHz, stamps jittered +-jitter_ns, uniform (a block at a time)."""
    from tskf_ros.bag.writer import BagWriter
    rng = np.random.default_rng(seed)
    with BagWriter(path) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        block = 100_000
        for start in range(0, n, block):
            k = np.arange(start, min(n, start + block))
            stamps = T0 + k * PERIOD_NS + rng.integers(-jitter_ns, jitter_ns + 1, len(k))
            values = 300.0 + 20.0 * np.sin(k / 700.0) + rng.normal(0.0, 2.0, len(k))
            for t, v in zip(stamps.tolist(), values.tolist()):
                w.write('/received_power', t + 200_000, illuminance_cdr(t, v, 4.0))


def peak_rss(command: list, env: dict, cwd: Path = REPO) -> tuple[float, float, str]:
    """Run command in cwd; return (peak RSS MB, wall s, last line of its output)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            env=env, cwd=cwd, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f'{command}: exit {proc.returncode}: {out[-2000:]}')
    lines = out.strip().splitlines()
    return usage.ru_maxrss / 1024, time.perf_counter() - t0, lines[-1] if lines else ''


def size_mb(path: Path) -> float:
    """Return the size of a file or a directory's files in MB."""
    if path.is_file():
        return path.stat().st_size / 1e6
    return sum(p.stat().st_size for p in path.rglob('*') if p.is_file()) / 1e6


def main() -> None:
    """Make the bags (once), run each case in a process, print peak RSS per size."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--sizes', type=int, nargs='+', default=[100_000, 1_000_000, 10_000_000])
    parser.add_argument('--work', type=Path, default=Path('/tmp/tskf_replay_memory'))
    parser.add_argument('--cases', nargs='*', default=['read', 'npz', 'bag'],
                        help=f'some of {", ".join(CASES)} (none: only make the bags)')
    parser.add_argument('--against', type=Path, metavar='DIR',
                        help="another commit's source tree, each case run with it too")
    args = parser.parse_args()
    unknown = set(args.cases) - set(CASES)
    if unknown:
        parser.error(f'--cases: unknown {sorted(unknown)}; expected some of {CASES}')
    args.work.mkdir(parents=True, exist_ok=True)
    params = args.work / 'params.yaml'
    params.write_text(PARAMS)
    env = dict(os.environ, OPENBLAS_NUM_THREADS='1')
    print(f'load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; python '
          f'{sys.version.split()[0]}', flush=True)
    print(f'{"messages":>10} {"case":<14} {"peak RSS MB":>11} {"wall s":>8} {"output MB":>9}',
          flush=True)
    for n in args.sizes:
        bag = args.work / f'jitter_{n}'
        if not (bag / 'metadata.yaml').exists():
            t0 = time.perf_counter()
            make_bag(bag, n)
            print(f'# wrote {bag} ({size_mb(bag):.0f} MB) in {time.perf_counter() - t0:.0f} s',
                  flush=True)
        trees = [('', None)] + ([(' before', args.against)] if args.against else [])
        plain: dict[tuple, float] = {}
        for case in args.cases:
            for label, tree in trees:
                run_env = env if tree is None else dict(env, PYTHONPATH=str(tree))
                rss, wall, made, smoothed = run_case(case, bag, params, args.work, run_env,
                                                     tree or REPO)
                note = ''
                if case in ('npz', 'bag'):
                    plain[(case, label)] = rss
                if smoothed and (case[:3], label) in plain:
                    growth = rss - plain[(case[:3], label)]
                    note = (f'   smoothed {smoothed:.0f} MB; growth over {case[:3]} '
                            f'{growth:.0f} MB = {growth / smoothed:.2f}x')
                print(f'{n:>10} {case + label:<14} {rss:>11.0f} {wall:>8.1f} {made:>9.0f}   '
                      f'(load {os.getloadavg()[0]:.2f}){note}', flush=True)


CASES = ('read', 'npz', 'bag', 'npz-smooth', 'bag-smooth', 'fit_noise', 'sweep')


def run_case(case: str, bag: Path, params: Path, work: Path, env: dict,
             tree: Path = REPO) -> tuple[float, float, float, float]:
    """
    Run one case in `tree`; return peak RSS MB, wall s, output MB, the smoothed MB (or 0).

    The process runs in the tree's folder: `python -m` puts the working directory first
    on sys.path, before PYTHONPATH, so run elsewhere it would import this tree's code.
    """
    tool = [sys.executable, '-m', 'tskf_ros.bag.replay.cli']
    out = work / ('out.npz' if case.startswith('npz') else 'out_bag' if case.startswith('bag')
                  else 'out.json' if case == 'fit_noise' else 'out.csv')
    smooth = ['--smooth'] if case.endswith('smooth') else []
    if case == 'read':
        command = [sys.executable, '-c', READ, str(bag)]
    elif case.startswith('npz'):
        command = tool + [str(bag), '--npz', str(out), '--params-file', str(params),
                          '--overwrite', '-q', *smooth]
    elif case.startswith('bag'):
        command = tool + [str(bag), str(out), '--params-file', str(params), '--overwrite',
                          '-q', *smooth]
    elif case == 'fit_noise':
        command = [sys.executable, '-m', 'tskf_ros.experiments.fit_noise', str(bag),
                   '--params-file', str(params), '--json', str(out), '-q']
    else:
        command = [sys.executable, '-m', 'tskf_ros.experiments.sweep', '--bags', str(bag),
                   '--params-file', str(params), '--workers', '0', '--out', str(out),
                   '--no-resume', '--no-progress']
    try:
        rss, wall, _ = peak_rss(command, env, tree)
        made = size_mb(out) if out.exists() else 0.0
        smoothed = 0.0
        if case == 'npz-smooth':
            with np.load(out) as z:
                smoothed = sum(z[k].nbytes for k in z.files
                               if k.startswith('estimate/smoothed.')) / 1e6
        elif case == 'bag-smooth':
            smoothed = _smoothed_mb(out)
        return rss, wall, made, smoothed
    finally:
        if out.is_dir():
            shutil.rmtree(out)
        elif out.exists():
            out.unlink()


def _smoothed_mb(bag: Path) -> float:
    """Return the in-memory size of a bag's smoothed rows: 8 (2 + n + n^2) bytes a message."""
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == '/estimate/smoothed']
        count = sum(c.msgcount for c in conns)
        if not count:
            return 0.0
        from rosbags.typesys import get_typestore, Stores
        store = get_typestore(Stores.ROS2_JAZZY)
        _, _, raw = next(reader.messages(connections=conns))
        # data = [sec, nanosec, mu, x (n), P (n x n)]
        size = len(store.deserialize_cdr(raw, conns[0].msgtype).data) - 3
    n = int(round((-1 + (1 + 4 * size) ** 0.5) / 2))
    return count * 8 * (2 + n + n * n) / 1e6


if __name__ == '__main__':
    main()
