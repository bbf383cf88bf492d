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
Benchmark: the estimator node on a 2 kHz stream from another process, over loopback DDS.

    python bench/bench_stream.py [--seconds 60] [--rate 2000] [--executor events]

Three processes: the node (`python -m tskf_ros.nodes.timescale_estimator --executor ...`,
period 1 / rate, its default queue depth), a publisher (this script with `publish`) that
sends Illuminance at `rate` Hz, reliable, paced by the wall clock, with sample k stamped
T0 + k / rate (the sequence number is in the stamp), and this process, which takes the
node's /diagnostics and its estimate/predicted.  Printed: sent, received by the node (its
own `received` counter, from /diagnostics once it stops changing), lost = the difference,
the predicted estimates that came back and the sequence numbers missing among them, the
publisher's achieved rate, and the node process's CPU (user + system, /proc) as a
percentage of one core over the stream.
"""

import argparse
import json
import os
from pathlib import Path
import signal
import struct
import subprocess
import sys
import tempfile
import time
from typing import Optional

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import Illuminance  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.messages.estimator_interface import default_parameters  # noqa: E402
from tskf_ros.nodes.node_runner import make_executor  # noqa: E402

from bench_estimator import OUTPUTS  # noqa: E402, I100 - bench/, next to this script

NS = 1_000_000_000
T0_NS = 1_000 * NS
# the estimate's data = [sec, nanosec, mu, x, P] of the OWC model (n = 1): the last 5 doubles
STAMP = struct.Struct('<dd')
ESTIMATE_DOUBLES = 5
TIMEOUT = 60.0          # s: a bound on discovery and on the node settling, never a result
WARMUP_RATE = 200.0     # Hz of a warm-up before the stream (publish's warmup)
WARMUP_PAUSE = 0.5      # s between the warm-up and the stream


def publish(namespace: str, rate: float, seconds: float, warmup: float = 0.0) -> None:
    """
    Publish rate Hz for seconds once the node matched; print {sent, wall} as JSON.

    With warmup > 0, first WARMUP_RATE Hz for warmup seconds (the same stamps, one period
    apart), a pause of WARMUP_PAUSE s, then the stream: the node's first inputs (its
    kernels are compiled, or loaded from numba's cache, as they come) before the rate.
    'streaming' is printed when the stream starts; `sent` counts the warm-up as well.
    """
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('stream', namespace=namespace, context=context)
    pub = node.create_publisher(Illuminance, 'measurement', QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    deadline = time.monotonic() + TIMEOUT
    while pub.get_subscription_count() < 1:
        if time.monotonic() > deadline:
            raise RuntimeError('the node never matched the publisher')
        time.sleep(0.01)
    print('matched', flush=True)
    period_ns = int(round(NS / rate))
    sent = 0
    for _ in range(int(round(WARMUP_RATE * warmup))):
        sent += 1
        pub.publish(conversions.power_to_msg(T0_NS + sent * period_ns,
                                             165.6 + (sent % 7) - 3.0))
        time.sleep(1.0 / WARMUP_RATE)
    if warmup > 0:
        time.sleep(WARMUP_PAUSE)
    print('streaming', flush=True)
    first = sent
    total = first + int(round(rate * seconds))
    start = time.perf_counter()
    while sent < total:
        due = min(total, first + int((time.perf_counter() - start) * rate) + 1)
        while sent < due:
            sent += 1
            pub.publish(conversions.power_to_msg(T0_NS + sent * period_ns,
                                                 165.6 + (sent % 7) - 3.0))
        time.sleep(max(0.0, start + (sent - first) / rate - time.perf_counter()))
    wall = time.perf_counter() - start
    node.destroy_node()
    context.try_shutdown()
    print(json.dumps({'sent': sent, 'wall': wall}), flush=True)


def stop_processes(publisher: Optional[subprocess.Popen], node: subprocess.Popen) -> None:
    """Kill the publisher if it still runs; stop the node with SIGINT (kill it after TIMEOUT)."""
    if publisher is not None and publisher.poll() is None:
        publisher.kill()
    node.send_signal(signal.SIGINT)
    try:
        node.wait(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        node.kill()


def cpu_seconds(pid: int) -> float:
    """Return the user + system CPU time (s) of a process so far, from /proc."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def main() -> None:
    """Run the node, the publisher and the monitor; print the figures."""
    if len(sys.argv) > 1 and sys.argv[1] == 'publish':
        publish(sys.argv[2], float(sys.argv[3]), float(sys.argv[4]),
                float(sys.argv[5]) if len(sys.argv) > 5 else 0.0)
        return
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--seconds', type=float, default=60.0)
    parser.add_argument('--rate', type=float, default=2000.0)
    parser.add_argument('--executor', default='events', choices=['single', 'events'])
    parser.add_argument('--outputs', default='all', choices=['all', 'predicted'],
                        help='subscribe to both outputs per input, or to '
                        'estimate/predicted only')
    depth = default_parameters()['queue_depth']
    parser.add_argument('--queue-depth', type=int, default=depth,
                        help=f"the node's queue_depth parameter (default: its default, {depth})")
    args = parser.parse_args()
    namespace = f'/stream{os.getpid()}'
    period_ns = int(round(NS / args.rate))
    print(f'{args.rate:g} Hz for {args.seconds:g} s, node on the {args.executor} executor, '
          f'queue depth {args.queue_depth}, subscribed outputs: {args.outputs}; load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs', flush=True)
    log = tempfile.TemporaryFile('w+')        # the node's log (a pipe could fill and block)
    node = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.nodes.timescale_estimator', '--executor',
         args.executor, '--ros-args', '-r', f'__ns:={namespace}',
         '-p', f'period:={1.0 / args.rate!r}', '-p', 'diagnostic_updater.period:=0.5',
         '-p', f'queue_depth:={args.queue_depth}',
         # every estimate is counted: the outputs keep as many as the input queue
         *[arg for topic in ('predicted', 'corrected') for arg in (
             '-p', f'qos_overrides.{namespace}/estimate/{topic}.publisher.depth:='
             f'{args.queue_depth}')],
         '--log-level', 'warn'], cwd=REPO, stdout=log, stderr=subprocess.STDOUT, text=True)
    context = Context()
    rclpy.init(context=context)
    monitor = rclpy.create_node('monitor', namespace=namespace, context=context)
    seen = set()
    received = []          # the node's 'received' counter, one entry per /diagnostics
    # the outputs are taken serialized (raw): this process must not be what limits the
    # node on a 2-core machine; the stamp is read from the CDR bytes (the estimate layout's
    # data, the message's last field: sec and nanosec as float64, little endian)

    def on_predicted(data: bytes) -> None:
        sec, nanosec = STAMP.unpack_from(data, len(data) - 8 * ESTIMATE_DOUBLES)
        seen.add((int(sec) * NS + int(nanosec) - T0_NS) // period_ns)
    monitor.create_subscription(Float64MultiArray, 'estimate/predicted',
                                on_predicted, QoSProfile(depth=10000), raw=True)

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for name, values in conversions.msg_to_diagnostics(msg).items():
            if name == 'timescale_estimator: filter health':
                received.append(int(values['Samples received']))
    monitor.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics,
                                QoSProfile(depth=100))
    others = {}
    if args.outputs == 'all':
        # the other output per input, taken and counted (the node publishes only the
        # outputs somebody subscribes to)
        for topic, cls in OUTPUTS:
            if topic != 'estimate/predicted':
                others[topic] = 0
                monitor.create_subscription(cls, topic, lambda m, t=topic: others.__setitem__(
                    t, others[t] + 1), QoSProfile(depth=10000), raw=True)
    executor = make_executor('events', context=context)
    executor.add_node(monitor)
    publisher = None
    try:
        deadline = time.monotonic() + TIMEOUT
        while not received or monitor.count_publishers('estimate/predicted') < 1:
            if time.monotonic() > deadline or node.poll() is not None:
                raise RuntimeError(f'the node never came up (exit {node.poll()})')
            executor.spin_once(timeout_sec=0.05)
        publisher = subprocess.Popen(
            [sys.executable, __file__, 'publish', namespace, str(args.rate),
             str(args.seconds)], stdout=subprocess.PIPE, text=True)
        if publisher.stdout.readline().strip() != 'matched':
            raise RuntimeError('the publisher ended before the node matched it')
        cpu0, t0 = cpu_seconds(node.pid), time.monotonic()
        while publisher.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        cpu1, t1 = cpu_seconds(node.pid), time.monotonic()
        result = json.loads(publisher.stdout.read().strip().splitlines()[-1])
        # the node's counter, once two /diagnostics in a row agree (it took all it will)
        deadline = time.monotonic() + TIMEOUT
        count = len(received)
        while not (len(received) >= count + 2 and received[-1] == received[-2]):
            if time.monotonic() > deadline:
                raise RuntimeError('the node never settled')
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        monitor.destroy_node()
        context.try_shutdown()
        stop_processes(publisher, node)
        log.seek(0)
        lines = log.read().splitlines()
        log.close()
    if lines:
        print(f'the node logged {len(lines)} lines; the last: {lines[-1][:200]}')
    sent = result['sent']
    taken = received[-1]
    missing = sent - len(seen & set(range(1, sent + 1)))
    print(f'sent {sent} at {sent / result["wall"]:.1f} Hz (publisher, {result["wall"]:.1f} s '
          f'wall); received by the node {taken}; lost {sent - taken} '
          f'({(sent - taken) / sent:.3%})')
    print(f'predicted estimates that came back: {len(seen)}, sequence numbers missing among '
          f'them: {missing}; other outputs taken: '
          + (', '.join(f'{t} {n}' for t, n in others.items()) or 'none subscribed'))
    print(f'node process CPU over the stream: {(cpu1 - cpu0) / (t1 - t0):.0%} of one core '
          f'({(cpu1 - cpu0) / sent * 1e6:.0f} us per input); node exit status '
          f'{node.returncode}')
    print(f'goal: {args.rate:g} Hz for {args.seconds:g} s with no input lost: '
          f'{"MET" if taken == sent else "NOT MET"}')


if __name__ == '__main__':
    main()
