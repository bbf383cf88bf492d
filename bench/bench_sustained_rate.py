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
Benchmark: the highest input rate the estimator node takes with nothing lost, against a relay.

    python bench/bench_sustained_rate.py [--rates 250,500,1000,1500,2000] [--seconds 10]
        [--load quiet,busy] [--executors single events] [--cases node relay]

For each load, executor and rate (ascending), and each case in turn at that rate, three
processes as in bench_stream.py: the case, pinned to CPU 0, the publisher
(`bench_stream.py publish`: Illuminance at the rate, reliable, paced by the wall clock,
pinned to CPU 1) and this process (pinned to CPU 1), which reads the case's /diagnostics
once it has settled.  The cases:

    node    `python -m tskf_ros.nodes.timescale_estimator --executor ...`, period 1 / rate
    relay   bench_estimator.py's Relay (the node's entities, the same two estimate
            messages filled and published per input, no filter) on the same executor

The rate sustained is measured after the start-up work (bench_startup.py's subject):
each stream is preceded by `--warmup` s (default 1) of the same stamps at 200 Hz and a
0.5 s pause; the node runs its kernels as its console script does where they are built
ahead of time (tskf_ros.core.aot), else with TSKF_JIT=wait, so that it loads its
compiled kernels (numba's cache) at its first input rather than in a background thread
while the stream comes ($TSKF_JIT, if set, is used as it is); `sent` and `received`
count the warm-up as well, and the CPU is the stream's.
`busy` adds a busy loop pinned to CPU 1: the other core is taken.  Drops by cause, from
the case's own counters (task 'filter health'):

    transport       'Messages lost (transport)': the middleware's message_lost count, a
                    gap in the publisher's sequence (a datagram that never arrived)
    queue overflow  sent - received - transport: messages that arrived but were replaced
                    in the subscription's keep-last queue (queue_depth) before the
                    executor took them

Printed: one row per (load, executor, rate, case), with the machine's 1-minute load
average after the run, and, per load and executor, each case's highest rate at which
nothing was lost (nor at any lower rate of the sweep; a case is not run again above a
rate where it lost), and the ratio node / relay (goal >= 0.7).
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
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from tskf_ros.core import aot  # noqa: E402
from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.nodes.node_runner import executor_kind, make_executor, spin  # noqa: E402

# bench/, next to this script
from bench_estimator import Relay  # noqa: E402, I100
from bench_stream import cpu_seconds, stop_processes  # noqa: E402, I100

STREAM = Path(__file__).resolve().parent / 'bench_stream.py'
TIMEOUT = 60.0          # s: a bound on discovery and on the node settling, never a result
NODE_CPU, OTHER_CPU = 0, 1
HEALTH = 'timescale_estimator: filter health'
DIAGNOSTICS_PERIOD = 0.5    # s: the cases' /diagnostics, read once the counters settle
GOAL = 0.7                  # the node's highest lossless rate >= GOAL x the relay's


def pinned(cpu: int):
    """Return a preexec_fn that pins the child process to one CPU."""
    return lambda: os.sched_setaffinity(0, {cpu})


def case_command(case: str, rate: float, executor: str, namespace: str) -> list[str]:
    """Return the command line of a case (node or relay) at a rate on an executor."""
    ros_args = ['--ros-args', '-r', f'__ns:={namespace}', '-p', f'period:={1.0 / rate!r}',
                '-p', f'diagnostic_updater.period:={DIAGNOSTICS_PERIOD!r}',
                '-p', 'status_period:=0.0', '--log-level', 'warn']
    if case == 'relay':
        return [sys.executable, __file__, 'relay', executor, *ros_args]
    return [sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator', '--executor',
            executor, *ros_args]


def relay(kind: str, args: list) -> None:
    """Run bench_estimator's Relay on an executor until SIGINT (the relay case's process)."""
    context = Context()
    rclpy.init(args=['relay', *args], context=context)
    node = Relay(context=context, diagnostics_period=DIAGNOSTICS_PERIOD)
    executor = make_executor(kind, context=context)
    executor.add_node(node)
    try:
        spin(executor, context)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


def kernel_mode() -> str:
    """
    Return the node's jit mode: $TSKF_JIT, else its own where the kernels are built.

    The node's own mode ('background') runs the kernels built ahead of time
    (tskf_ros.core.aot: no compiling at all); without them 'wait' loads numba's cache at
    the first input rather than compiling in a thread while the stream runs.
    """
    return os.environ.get('TSKF_JIT') or ('background' if aot.load() is not None else 'wait')


def run_once(case: str, rate: float, seconds: float, executor: str,
             warmup: float = 0.0) -> dict:
    """Stream rate Hz for seconds into a fresh case (after a warm-up); return the counts."""
    namespace = f'/sustained{os.getpid()}_{case}_{int(rate)}'
    case = case.rstrip('0123456789')        # relay2: a second run of the relay
    log = tempfile.TemporaryFile('w+')
    env = dict(os.environ, TSKF_JIT=kernel_mode())
    node = subprocess.Popen(case_command(case, rate, executor, namespace), cwd=REPO,
                            stdout=log, stderr=subprocess.STDOUT, text=True, env=env,
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
            [sys.executable, str(STREAM), 'publish', namespace, str(rate), str(seconds),
             str(warmup)], stdout=subprocess.PIPE, text=True, preexec_fn=pinned(OTHER_CPU))
        if publisher.stdout.readline().strip() != 'matched':
            raise RuntimeError('the publisher ended before the node matched it')
        if publisher.stdout.readline().strip() != 'streaming':
            raise RuntimeError('the publisher ended in its warm-up')
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
    """Sweep the rates per load and executor; print the rows and the highest lossless rates."""
    if len(sys.argv) > 2 and sys.argv[1] == 'relay':
        relay(sys.argv[2], sys.argv[3:])
        return
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--rates', default='250,500,1000,1500,2000',
                        help='comma-separated Hz, swept in ascending order')
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--warmup', type=float, default=1.0,
                        help='s of 200 Hz before each stream (0: none; see the docstring)')
    parser.add_argument('--load', default='quiet,busy',
                        help='comma-separated: quiet, busy (a busy loop on the other CPU)')
    parser.add_argument('--executors', nargs='+', default=None, choices=['single', 'events'],
                        help="the executors of both cases (default: the node's default)")
    parser.add_argument('--cases', nargs='+', default=['node', 'relay'],
                        choices=['node', 'relay'],
                        help='a case given twice runs twice, as relay and relay2 (a '
                             'control: how far two runs of one case differ)')
    args = parser.parse_args()
    args.cases = [c + (str(args.cases[:i + 1].count(c)) if args.cases[:i].count(c) else '')
                  for i, c in enumerate(args.cases)]
    rates = sorted(float(r) for r in args.rates.split(','))
    if os.cpu_count() < 2:
        sys.exit('bench_sustained_rate: needs two CPUs (the case on one, the rest on the '
                 'other)')
    os.sched_setaffinity(0, {OTHER_CPU})
    executors = args.executors or [executor_kind()]
    print(f'{args.seconds:g} s per rate, the case on CPU {NODE_CPU} ({", ".join(executors)}'
          f' executor), publisher and monitor on CPU {OTHER_CPU}; load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; the node with '
          f'TSKF_JIT={kernel_mode()}', flush=True)
    print('load  executor case   rate Hz     sent  received  transport  overflow  CPU  '
          'load avg', flush=True)
    for load in args.load.split(','):
        busy = busy_loop() if load == 'busy' else None
        try:
            for executor in executors:
                best = sweep(load, executor, args.cases, rates, args.seconds, args.warmup)
                for case in args.cases:
                    print(f'{load} {executor}: {case} highest rate with nothing lost: '
                          + (f'{best[case]:g} Hz' if best[case] is not None
                             else f'none (lost at {rates[0]:g} Hz)'), flush=True)
                if best.get('node') and best.get('relay'):
                    ratio = best['node'] / best['relay']
                    print(f'{load} {executor}: node / relay {ratio:.2f}: '
                          f'{"MET" if ratio >= GOAL else "NOT MET"} (goal >= {GOAL:g})',
                          flush=True)
        finally:
            if busy is not None:
                busy.kill()
                busy.wait()


def sweep(load: str, executor: str, cases: list, rates: list, seconds: float,
          warmup: float) -> dict:
    """Run each case at each rate, ascending, until it loses; return its highest lossless."""
    best: dict = {case: None for case in cases}
    lost: set = set()
    for rate in rates:
        for case in cases:
            if case in lost:
                continue
            r = run_once(case, rate, seconds, executor, warmup)
            print(f'{load:5} {executor:8} {case:5} {rate:8g} {r["sent"]:8d} '
                  f'{r["received"]:9d} {r["transport"]:10d} {r["overflow"]:9d} '
                  f'{r["cpu"]:4.0%} {os.getloadavg()[0]:9.2f}', flush=True)
            if r['received'] == r['sent']:
                best[case] = rate       # nothing lost at this rate nor any below it
            else:
                lost.add(case)
        if len(lost) == len(cases):
            break
    return best


if __name__ == '__main__':
    main()
