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
Benchmark: the estimator node's resident memory (VmRSS) under a 2 kHz flood over loopback DDS.

    python bench/bench_memory.py [--rate 2000] [--seconds 65] [--executor single]

Two processes as in bench_stream.py: the node (`python -m tskf_ros.nodes.timescale_estimator`,
period 1 / rate, its default parameters otherwise) and the publisher (`bench_stream.py
publish`: Illuminance at the rate, reliable, paced by the wall clock).  This process reads
the node's VmRSS from /proc/PID/status once a second from the moment the publisher matched
until it has sent everything, and prints the samples, the values at the start, at 35 s and
at the end, and the growth over the second half (after the first 5 s, which fill the queue,
the caches and the history).
"""

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from bench_stream import cpu_seconds, stop_processes  # noqa: I100 - bench/, next to this script

REPO = Path(__file__).resolve().parent.parent
STREAM = Path(__file__).resolve().parent / 'bench_stream.py'
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
TIMEOUT = 60.0          # s: a bound on discovery and on the node's exit, never a result
WARM_UP = 5             # s of the stream before the growth is counted
MIDDLE = 35             # s: the sample between the two halves of the growth


def vm_rss_kib(pid: int) -> int:
    """Return a process's resident set size in KiB (VmRSS of /proc/PID/status)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1])
    raise RuntimeError(f'no VmRSS for process {pid}')


def main() -> None:
    """Flood the node for --seconds; print its VmRSS once a second and the summary."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rate', type=float, default=2000.0)
    parser.add_argument('--seconds', type=int, default=65)
    parser.add_argument('--executor', default='single', choices=['single', 'events'])
    args = parser.parse_args()
    namespace = f'/memory{os.getpid()}'
    ros = ['--executor', args.executor, '--ros-args', '-r', f'__ns:={namespace}',
           '-p', f'period:={1.0 / args.rate!r}', '--log-level', 'warn']
    command = [sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator', *ros]
    print(f'{args.rate:g} Hz for {args.seconds} s into the node ({args.executor} executor); '
          f'load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs', flush=True)
    log = tempfile.TemporaryFile('w+')
    node = subprocess.Popen(command, cwd=REPO, stdout=log, stderr=subprocess.STDOUT, text=True)
    publisher = None
    samples: list[int] = []
    try:
        publisher = subprocess.Popen(
            [sys.executable, str(STREAM), 'publish', namespace, str(args.rate),
             str(args.seconds)], stdout=subprocess.PIPE, text=True)
        if publisher.stdout.readline().strip() != 'matched':
            raise RuntimeError('the publisher ended before the node matched it')
        idle = vm_rss_kib(node.pid)
        cpu0 = cpu_seconds(node.pid)
        start = time.monotonic()
        for second in range(args.seconds + 1):
            # a sampling period, not a synchronisation: the flood runs on its own
            time.sleep(max(0.0, start + second - time.monotonic()))
            if node.poll() is not None:
                raise RuntimeError(f'the node ended (exit {node.returncode})')
            samples.append(vm_rss_kib(node.pid))
        cpu = (cpu_seconds(node.pid) - cpu0) / (time.monotonic() - start)
        sent = json.loads(publisher.communicate(timeout=TIMEOUT)[0].strip().splitlines()[-1])
    finally:
        stop_processes(publisher, node)
        log.close()
    print('s  VmRSS MiB')
    for second, kib in enumerate(samples):
        print(f'{second:3d} {kib / 1024:8.1f}')
    mid = min(MIDDLE, len(samples) - 1)
    mib = [kib / 1024 for kib in samples]
    print(f'sent {sent["sent"]} in {sent["wall"]:.1f} s; load average {os.getloadavg()[0]:.2f}')
    print(f'VmRSS before the stream {idle / 1024:.1f} MiB; at 0 s {mib[0]:.1f}, '
          f'{WARM_UP} s {mib[WARM_UP]:.1f}, {mid} s {mib[mid]:.1f}, '
          f'{len(mib) - 1} s {mib[-1]:.1f} MiB')
    print(f'node CPU over the stream: {cpu:.0%} of one core')
    print(f'growth from {WARM_UP} s to {mid} s: {mib[mid] - mib[WARM_UP]:+.1f} MiB; '
          f'from {mid} s to the end: {mib[-1] - mib[mid]:+.1f} MiB '
          f'(max {max(mib):.1f} MiB at {mib.index(max(mib))} s)')


if __name__ == '__main__':
    main()
