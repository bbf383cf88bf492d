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
Benchmark: the highest input rate the estimator node takes with nothing lost, quiet and loaded.

    python bench/bench_sustained_rate.py [--rates 250,500,1000,1500,2000] [--seconds 10]
        [--load quiet,busy] [--executor events]

For each load and each rate (ascending), three processes as in bench_stream.py: the node
(`python -m tskf_ros.nodes.timescale_estimator`, period 1 / rate, pinned to CPU 0), the
publisher (`bench_stream.py publish`: Illuminance at the rate, reliable, paced by the wall
clock, pinned to CPU 1) and this process (pinned to CPU 1), which reads the node's
/diagnostics once it has settled.  `busy` adds a busy loop pinned to CPU 1: the other core
is taken.  Drops by cause, from the node's own counters (task 'filter health'):

    transport       'Messages lost (transport)': the middleware's message_lost count, a
                    gap in the publisher's sequence (a datagram that never arrived)
    queue overflow  sent - received - transport: messages that arrived but were replaced
                    in the subscription's keep-last queue (queue_depth) before the
                    executor took them

Printed: one row per (load, rate), with the machine's 1-minute load average after the run,
and, per load, the highest rate at which nothing was lost (nor at any lower rate of the
sweep).
"""

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.nodes.node_runner import make_executor  # noqa: E402

# bench/, next to this script
from bench_stream import cpu_seconds, stop_processes  # noqa: E402, I100

STREAM = Path(__file__).resolve().parent / 'bench_stream.py'
TIMEOUT = 60.0          # s: a bound on discovery and on the node settling, never a result
NODE_CPU, OTHER_CPU = 0, 1
HEALTH = 'timescale_estimator: filter health'


def pinned(cpu: int):
    """Return a preexec_fn that pins the child process to one CPU."""
    return lambda: os.sched_setaffinity(0, {cpu})


def run_once(rate: float, seconds: float, executor: str) -> dict:
    """Stream rate Hz for seconds into a fresh node; return sent, received, lost, CPU."""
    namespace = f'/sustained{os.getpid()}_{int(rate)}'
    log = tempfile.TemporaryFile('w+')
    node = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator', '--executor', executor,
         '--ros-args', '-r', f'__ns:={namespace}', '-p', f'period:={1.0 / rate!r}',
         '-p', 'diagnostic_updater.period:=0.5', '-p', 'status_period:=0.0',
         '--log-level', 'warn'], cwd=REPO, stdout=log, stderr=subprocess.STDOUT, text=True,
        preexec_fn=pinned(NODE_CPU))
    context = Context()
    rclpy.init(context=context)
    monitor = rclpy.create_node('monitor', namespace=namespace, context=context)
    seen: list[tuple[int, int]] = []    # (received, lost in transport) per /diagnostics

    def on_diagnostics(msg: DiagnosticArray) -> None:
        health = conversions.msg_to_diagnostics(msg).get(HEALTH)
        if health is not None:
            seen.append((int(health['Samples received']),
                         int(health['Messages lost (transport)'])))
    monitor.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics,
                                QoSProfile(depth=100))
    spinner = make_executor('single', context=context)
    spinner.add_node(monitor)
    publisher = None
    try:
        deadline = time.monotonic() + TIMEOUT
        while not seen:
            if time.monotonic() > deadline or node.poll() is not None:
                raise RuntimeError(f'the node never came up (exit {node.poll()})')
            spinner.spin_once(timeout_sec=0.05)
        publisher = subprocess.Popen(
            [sys.executable, str(STREAM), 'publish', namespace, str(rate), str(seconds)],
            stdout=subprocess.PIPE, text=True, preexec_fn=pinned(OTHER_CPU))
        if publisher.stdout.readline().strip() != 'matched':
            raise RuntimeError('the publisher ended before the node matched it')
        cpu0, t0 = cpu_seconds(node.pid), time.monotonic()
        while publisher.poll() is None:
            spinner.spin_once(timeout_sec=0.05)
        cpu1, t1 = cpu_seconds(node.pid), time.monotonic()
        sent = json.loads(publisher.stdout.read().strip().splitlines()[-1])['sent']
        deadline = time.monotonic() + TIMEOUT
        count = len(seen)
        while not (len(seen) >= count + 2 and seen[-1] == seen[-2]):
            if time.monotonic() > deadline:
                raise RuntimeError('the node never settled')
            spinner.spin_once(timeout_sec=0.05)
    finally:
        spinner.shutdown()
        monitor.destroy_node()
        context.try_shutdown()
        stop_processes(publisher, node)
        log.close()
    received, transport = seen[-1]
    return {'rate': rate, 'sent': sent, 'received': received, 'transport': transport,
            'overflow': max(sent - received - transport, 0),
            'cpu': (cpu1 - cpu0) / (t1 - t0)}


def busy_loop() -> subprocess.Popen:
    """Start a process that spins on the other CPU."""
    return subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                            preexec_fn=pinned(OTHER_CPU))


def main() -> None:
    """Sweep the rates under each load; print the rows and the highest rate with no loss."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rates', default='250,500,1000,1500,2000',
                        help='comma-separated Hz, swept in ascending order')
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--load', default='quiet,busy',
                        help='comma-separated: quiet, busy (a busy loop on the other CPU)')
    parser.add_argument('--executor', default=None, choices=['single', 'events'],
                        help="the node's executor (default: the node's default)")
    args = parser.parse_args()
    rates = sorted(float(r) for r in args.rates.split(','))
    if os.cpu_count() < 2:
        sys.exit('bench_sustained_rate: needs two CPUs (the node on one, the rest on the '
                 'other)')
    os.sched_setaffinity(0, {OTHER_CPU})
    executor = args.executor or os.environ.get('TSKF_EXECUTOR') or 'events'
    print(f'{args.seconds:g} s per rate, node on CPU {NODE_CPU} ({executor} executor), '
          f'publisher and monitor on CPU {OTHER_CPU}; load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs', flush=True)
    print('load   rate Hz     sent  received  transport  overflow  node CPU  load avg',
          flush=True)
    for load in args.load.split(','):
        busy = busy_loop() if load == 'busy' else None
        best = previous = None
        try:
            for rate in rates:
                r = run_once(rate, args.seconds, executor)
                print(f'{load:5} {rate:8g} {r["sent"]:8d} {r["received"]:9d} '
                      f'{r["transport"]:10d} {r["overflow"]:9d} {r["cpu"]:8.0%} '
                      f'{os.getloadavg()[0]:9.2f}', flush=True)
                if r['received'] == r['sent'] and best == previous:
                    best = rate         # nothing lost at this rate nor any below it
                previous = rate
        finally:
            if busy is not None:
                busy.kill()
                busy.wait()
        print(f'{load}: highest rate with nothing lost: '
              + (f'{best:g} Hz' if best is not None else f'none (lost at {rates[0]:g} Hz)'),
              flush=True)


if __name__ == '__main__':
    main()
