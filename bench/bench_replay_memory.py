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
- replay -> bag: `replay_offline BAG OUT` (the output bag written as it goes).

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


def peak_rss(command: list, env: dict) -> tuple[float, float, str]:
    """Run command; return (peak RSS MB, wall s, last line of its output)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            env=env, cwd=REPO, text=True)
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
                        help='read, npz, bag (none: only make the bags)')
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    params = args.work / 'params.yaml'
    params.write_text(PARAMS)
    env = dict(os.environ, OPENBLAS_NUM_THREADS='1')
    tool = [sys.executable, '-m', 'tskf_ros.bag.replay.cli']
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
        for case in args.cases:
            out = args.work / ('out.npz' if case == 'npz' else 'out_bag')
            if case == 'read':
                command = [sys.executable, '-c', READ, str(bag)]
            elif case == 'npz':
                command = tool + [str(bag), '--npz', str(out), '--params-file', str(params),
                                  '--overwrite', '-q']
            else:
                command = tool + [str(bag), str(out), '--params-file', str(params),
                                  '--overwrite', '-q']
            rss, wall, _ = peak_rss(command, env)
            made = size_mb(out) if out.exists() else 0.0
            print(f'{n:>10} {case:<14} {rss:>11.0f} {wall:>8.1f} {made:>9.0f}   '
                  f'(load {os.getloadavg()[0]:.2f})', flush=True)
            if out.is_dir():
                shutil.rmtree(out)
            elif out.exists():
                out.unlink()


if __name__ == '__main__':
    main()
