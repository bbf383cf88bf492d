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
Benchmark: the estimator node against a relay that publishes the same messages.

    python bench/bench_estimator.py [--messages 3000] [--repeats 5] [--executors single events]
                                    [--cases relay node stub]

Each case runs in a process of its own (this script with `worker`), spinning as
`python -m tskf_ros.nodes.timescale_estimator --executor ...` does (node_runner.spin; the
node and the stub with their heap frozen, own_process(), as run_node does):

- node: TimescaleEstimator on the OWC model (3), period 1 ms;
- relay: a node with the same entities (measurement and input subscriptions, the first
  with a message_lost handler, the same output publishers, /diagnostics on a 1 s timer,
  ~/reset, the parameter services)
  that fills preallocated messages of the same types from each input and publishes the
  same two per input (predicted and corrected, Float64MultiArray estimates), no filter;
- stub: the node with a session that filters nothing (StubSession: a fixed steady-state
  outcome at each stamp), so that node - stub is the session's cost in place.

The node and the stub run the kernels as the node's console script does ($TSKF_JIT, else
'background': the kernels built ahead of time, tskf_ros.core.aot, where they are), and
so does the in-process part; the first line says which form ran.

A driver in this process publishes Illuminance samples 1 ms apart (the stamp is the
sequence number), keeping at most `--window` without their predicted estimate, and
subscribes to the two outputs with the same types in both cases.  The worker measures,
between its warm-up'th and last input, the CPU time of its executor thread
(time.thread_time), of its whole process (DDS threads included) and the wall time.  The
cases alternate (relay, node, stub, relay, ...) for `--repeats` rounds per executor;
min and median are printed, and the ratio node / relay with the goal (<= 1.3 on
SingleThreadedExecutor, <= 1.5 on EventsExecutor).
Then the in-process cost of the parts of the node's callback, on the same stream.
"""

import argparse
import json
import os
from pathlib import Path
import platform
import resource
import statistics
import subprocess
import sys
import time
import timeit

# runnable from a source checkout without installing: the repository root on the path
REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import AccelStamped  # noqa: E402
import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks  # noqa: E402
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import Illuminance  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from tskf_ros.core import jit, kalman  # noqa: E402
from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.messages.estimator_interface import (load_config, outcome_messages,  # noqa: E402
                                                   OutcomeMessages, output_qos,
                                                   OUTPUT_TOPICS)
from tskf_ros.messages.qos import DEFAULT_DEPTH, sensor_input_qos  # noqa: E402
from tskf_ros.nodes.node_runner import make_executor, spin  # noqa: E402
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator  # noqa: E402
from tskf_ros.owc.session import Estimate, EstimatorSession, Jump, Outcome  # noqa: E402

NS = 1_000_000_000
PERIOD_NS = 1_000_000                       # the stream: one sample per ms of stamp time
T0_NS = 1_000 * NS
# the node's parameters for this stream (everything else: the defaults, model (3))
NODE_PARAMETERS = {'period': PERIOD_NS / NS}
# what the node publishes per input in steady state: (topic, type), the relay the same
OUTPUTS = [(OUTPUT_TOPICS[kind], Float64MultiArray) for kind in ('corrected', 'predicted')]
# node CPU per input <= GOAL x the relay's, per executor
GOAL = {'single': 1.3, 'events': 1.5}


def use_the_nodes_kernels() -> str:
    """
    Run the kernels as the node's console script does; return which form runs them.

    The jit mode $TSKF_JIT, else 'background' (node_runner.run_node's default): the kernels
    built ahead of time (tskf_ros.core.aot) where they are, else numba's dispatchers.
    """
    jit.set_mode(os.environ.get(jit.MODE_VARIABLE) or 'background')
    x, P = np.zeros(1), np.eye(1)
    kalman.mahalanobis2_into(x, P, x, P, P, x, np.empty(1))     # the node's gate
    jit.ready(timeout=600.0)     # numba's, where nothing was built ahead of time
    state = repr(kalman.mahalanobis2_into)
    return state[state.rindex('(') + 1:-2]


def power(k: int) -> float:
    """Return sample k's received power in mW: model (3)'s y at x0 plus deterministic noise."""
    return 165.6 + 10.0 * np.sin(0.7 * k)


class Relay(Node):
    """
    The node's entities and output messages, without the filter.

    Its /diagnostics message holds the node's two counters of inputs in its 'filter
    health' status: 'Samples received' and 'Messages lost (transport)' (the middleware's
    message_lost event, as the node counts it), which bench_sustained_rate.py reads.
    """

    def __init__(self, *, context=None, parameter_overrides=None,
                 diagnostics_period: float = 0.0) -> None:
        super().__init__('timescale_estimator', context=context,
                         parameter_overrides=parameter_overrides)
        config = load_config(overrides=NODE_PARAMETERS)
        qos_in = sensor_input_qos(config.queue_depth)
        self.received = self.lost = 0
        self.create_subscription(
            Illuminance, 'measurement', self._on_measurement, qos_in,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost))
        self.create_subscription(AccelStamped, 'input', lambda msg: None, qos_in)
        qos_out = output_qos(config)
        self.pubs = [self.create_publisher(cls, topic, qos_out) for topic, cls in OUTPUTS]
        # the node's other output publisher (estimate/revised), idle in steady state
        self.create_publisher(Float64MultiArray, OUTPUT_TOPICS['revised'], qos_out)
        self.diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', DEFAULT_DEPTH)
        self.create_timer(diagnostics_period or config.diagnostics_period,
                          self._publish_diagnostics)
        self.create_service(Trigger, '~/reset', lambda request, response: response)
        names = config.session.model.state_names
        self.msgs = [Float64MultiArray(layout=conversions.state_estimate_layout(kind, names))
                     for kind in ('corrected', 'predicted')]

    def _on_lost(self, info: QoSMessageLostInfo) -> None:
        self.lost = info.total_count

    def _publish_diagnostics(self) -> None:
        counts = {'Samples received': self.received, 'Messages lost (transport)': self.lost}
        self.diag_pub.publish(DiagnosticArray(status=[DiagnosticStatus(
            name=f'{self.get_name()}: filter health',
            values=[KeyValue(key=k, value=str(v)) for k, v in counts.items()])]))

    def _on_measurement(self, msg: Illuminance) -> None:
        self.received += 1
        stamp = msg.header.stamp
        data = [float(stamp.sec), float(stamp.nanosec), PERIOD_NS / NS, msg.illuminance, 0.0]
        for pub, out in zip(self.pubs, self.msgs):
            out.data = data
            pub.publish(out)


class Meter:
    """Count inputs; measure CPU and wall time from the warm-up'th to the last; then stop."""

    def __init__(self, warmup: int, messages: int, context: Context) -> None:
        self.count, self.warmup, self.last, self.context = 0, warmup, warmup + messages, context
        self.start = self.result = None

    def tick(self) -> None:
        """Call after each input's callback."""
        self.count += 1
        if self.count == self.warmup:
            self.start = self.sample()
        elif self.count == self.last:
            end = self.sample()
            self.result = {k: end[k] - self.start[k] for k in end}
            self.result['messages'] = self.last - self.warmup
            self.context.try_shutdown()

    @staticmethod
    def sample() -> dict:
        """Return the clocks: executor thread CPU, process CPU, wall (s)."""
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return {'thread_cpu': time.thread_time(), 'process_cpu': usage.ru_utime + usage.ru_stime,
                'wall': time.perf_counter()}


class StubSession:
    """A session that filters nothing: add() returns a steady-state Outcome at the stamp."""

    def __init__(self, session: EstimatorSession) -> None:
        self.session, self.stats = session, session.stats
        self.x, self.P = session.kf.x.copy(), session.kf.P.copy()

    def add(self, stamp_ns: int, value: float, variance: float = 0.0, *,
            now_ns: int = None) -> Outcome:
        """Count the sample; return corrected at stamp_ns, predicted and mu 1 ms on."""
        self.stats.received += 1
        return Outcome('accepted', estimates=[
            Estimate('corrected', stamp_ns, self.x, self.P),
            Estimate('predicted', stamp_ns + PERIOD_NS, self.x, self.P)],
            jumps=[Jump(stamp_ns, stamp_ns + PERIOD_NS)])

    def __getattr__(self, name: str):
        return getattr(self.session, name)


class StubbedEstimator(TimescaleEstimator):
    """The estimator node with a session that filters nothing (the node's cost minus it)."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.session = StubSession(self.session)


def metered(cls: type, meter: Meter) -> type:
    """Return a subclass of cls whose measurement callback ticks the meter."""
    class Metered(cls):
        def _on_measurement(self, msg):
            super()._on_measurement(msg)
            meter.tick()
    return Metered


def worker(kind: str, executor_kind: str, warmup: int, messages: int, ros_args: list) -> None:
    """Run the node or the relay until it has taken warmup + messages inputs; print JSON."""
    kernels = use_the_nodes_kernels() if kind != 'relay' else ''
    context = Context()
    rclpy.init(args=['worker', '--ros-args', *ros_args], context=context)
    meter = Meter(warmup, messages, context)
    cls = metered({'node': TimescaleEstimator, 'stub': StubbedEstimator, 'relay': Relay}[kind],
                  meter)
    node = cls(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in NODE_PARAMETERS.items()])
    if kind != 'relay':
        node.own_process()      # as node_runner.run_node does in the node's own process
    executor = make_executor(executor_kind, context=context)
    executor.add_node(node)
    try:
        spin(executor, context)
    except ExternalShutdownException:
        pass                    # EventsExecutor's spin_once, after the meter's shutdown
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    print(json.dumps(dict(meter.result, kernels=kernels)), flush=True)


class Driver:
    """Publish the stream into a worker's namespace and take its two outputs."""

    def __init__(self, context: Context, namespace: str, window: int) -> None:
        self.node = rclpy.create_node('driver', namespace=namespace, context=context)
        self.pub = self.node.create_publisher(Illuminance, 'measurement',
                                              QoSProfile(depth=1000))
        self.window, self.sent, self.acked = window, 0, 0
        self.stalls = 0         # times no estimate came for 1 s: the window was reopened
        self.counts = [0] * len(OUTPUTS)
        for i, (topic, cls) in enumerate(OUTPUTS):
            self.node.create_subscription(cls, topic, self._counter(i, topic),
                                          QoSProfile(depth=1000))

    def _counter(self, i: int, topic: str):
        def count(msg) -> None:
            self.counts[i] += 1
            if topic == 'estimate/predicted':
                seq = (conversions.msg_to_state_estimate(msg).stamp_ns - T0_NS) // PERIOD_NS
                self.acked = max(self.acked, seq)
        return count

    def ready(self) -> bool:
        """Return whether the worker matched our publisher and we its two outputs."""
        return self.pub.get_subscription_count() >= 1 and all(
            self.node.count_publishers(topic) >= 1 for topic, _ in OUTPUTS)

    def send_window(self) -> None:
        """Publish while fewer than `window` samples wait for their estimate."""
        while self.sent - self.acked < self.window:
            self.sent += 1
            self.pub.publish(conversions.power_to_msg(T0_NS + self.sent * PERIOD_NS,
                                                      power(self.sent)))


def run_case(kind: str, executor_kind: str, args: argparse.Namespace, case: int,
             context: Context, executor) -> dict:
    """Run one worker with a driver; return its measurements and the driver's counts."""
    namespace = f'/bench{os.getpid()}_{case}'
    cmd = [sys.executable, __file__, 'worker', kind, executor_kind, str(args.warmup),
           str(args.messages), '--ros-args', '-r', f'__ns:={namespace}']
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    driver = Driver(context, namespace, args.window)
    executor.add_node(driver.node)
    try:
        deadline = time.monotonic() + 60.0
        while not driver.ready():
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError(f'{kind}: the worker never matched (exit {proc.poll()})')
            executor.spin_once(timeout_sec=0.01)
        stalled_since = time.monotonic()
        while proc.poll() is None:
            acked = driver.acked
            driver.send_window()
            executor.spin_once(timeout_sec=0.01)
            if driver.acked != acked:
                stalled_since = time.monotonic()
            elif time.monotonic() - stalled_since > 1.0:
                # a best-effort input was lost (or the worker is slow): open the window
                driver.acked, stalled_since = driver.sent, time.monotonic()
                driver.stalls += 1
        out, _ = proc.communicate(timeout=60.0)
    finally:
        executor.remove_node(driver.node)
        driver.node.destroy_node()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    result = json.loads(out.strip().splitlines()[-1])
    result.update(sent=driver.sent, outputs=list(driver.counts),
                  stalls=driver.stalls)
    return result


def per_input_us(results: list, key: str) -> list:
    """Return the key's time per input in us, one value per repeat."""
    return [r[key] / r['messages'] * 1e6 for r in results]


def fmt(values: list, unit: str = 'us') -> str:
    """Return 'min / median unit'."""
    return f'{min(values):7.1f} / {statistics.median(values):7.1f} {unit}'


def in_process_costs(messages: int, repeat: int = 3) -> dict:
    """Return the us per input of the parts of the node's callback, on the same stream."""
    config = load_config(overrides=NODE_PARAMETERS)
    stamps = [T0_NS + k * PERIOD_NS for k in range(1, messages + 1)]
    values = [power(k) for k in range(1, messages + 1)]

    def run_session() -> list:
        session = EstimatorSession(config.session)
        return [session.add(t, y) for t, y in zip(stamps, values)]
    outcomes = run_session()
    reused = OutcomeMessages(config)

    def fill() -> None:
        for out in outcomes:
            for _ in reused.messages(out):
                pass

    def fill_and_serialize() -> None:
        for out in outcomes:
            for _, msg in reused.messages(out):
                serialize_message(msg)

    def build_and_serialize() -> None:
        for out in outcomes:
            for _, msg in outcome_messages(out, config):
                serialize_message(msg)

    def encode() -> None:
        for out in outcomes:
            reused.serialized(out)
    parts = {'session.add': run_session,
             'build 2 messages (outcome_messages)': lambda: [
                 outcome_messages(o, config) for o in outcomes],
             'fill 2 reused (OutcomeMessages)': fill,
             'build + serialize_message': build_and_serialize,
             'fill + serialize_message': fill_and_serialize,
             'serialized, as the node publishes (OutcomeMessages.serialized)': encode}
    return {name: min(timeit.repeat(f, timer=time.thread_time, number=1, repeat=repeat))
            / messages * 1e6
            for name, f in parts.items()}


def main() -> None:
    """Run the cases alternately and print the figures."""
    if len(sys.argv) > 1 and sys.argv[1] == 'worker':
        kind, executor_kind, warmup, messages = sys.argv[2:6]
        worker(kind, executor_kind, int(warmup), int(messages), sys.argv[7:])
        return
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--messages', type=int, default=3000)
    parser.add_argument('--warmup', type=int, default=300)
    parser.add_argument('--window', type=int, default=20)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--cases', nargs='+', default=['relay', 'node', 'stub'],
                        choices=['relay', 'node', 'stub'],
                        help='stub: the node with a session that filters nothing')
    parser.add_argument('--executors', nargs='+', default=['single', 'events'],
                        choices=['single', 'events'])
    args = parser.parse_args()
    kernels = use_the_nodes_kernels()
    print(f'kernels: {kernels} ({jit.MODE_VARIABLE}={jit.mode()}, as the node runs them)')
    print(f'machine: {platform.machine()}, {os.cpu_count()} CPUs, load average '
          f'{os.getloadavg()[0]:.2f}, Python {platform.python_version()}, numpy '
          f'{np.__version__}; {args.messages} inputs per case after {args.warmup} warm-up, '
          f'window {args.window}, {args.repeats} rounds, relay and node alternating')
    context = Context()
    rclpy.init(context=context)
    executor = make_executor('single', context=context)
    results = {}
    case = 0
    try:
        for executor_kind in args.executors:
            for _ in range(args.repeats):
                for kind in args.cases:
                    case += 1
                    r = run_case(kind, executor_kind, args, case, context, executor)
                    results.setdefault((executor_kind, kind), []).append(r)
                    print(f'  {executor_kind:6s} {kind:5s} thread '
                          f'{r["thread_cpu"] / r["messages"] * 1e6:7.1f} us, process '
                          f'{r["process_cpu"] / r["messages"] * 1e6:7.1f} us per input, '
                          f'{r["messages"] / r["wall"]:6.0f} inputs/s; outputs '
                          f'{r["outputs"]} for {r["sent"]} sent, {r["stalls"]} stalls'
                          + (f', kernels {r["kernels"]}' if r['kernels'] not in ('', kernels)
                             else ''),
                          flush=True)
    finally:
        executor.shutdown()
        context.try_shutdown()
    print('per input, min / median over the rounds:')
    print(f'{"executor":8s} {"case":5s} {"executor thread CPU":>22s} {"process CPU":>22s} '
          f'{"wall rate":>24s}')
    for (executor_kind, kind), rs in results.items():
        rate = [r['messages'] / r['wall'] for r in rs]
        print(f'{executor_kind:8s} {kind:5s} {fmt(per_input_us(rs, "thread_cpu")):>22s} '
              f'{fmt(per_input_us(rs, "process_cpu")):>22s} '
              f'{max(rate):8.0f} / {statistics.median(rate):6.0f} inputs/s')
    for executor_kind in args.executors:
        relay, node = results[(executor_kind, 'relay')], results[(executor_kind, 'node')]
        for key, what in (('thread_cpu', 'executor thread CPU'),
                          ('process_cpu', 'process CPU')):
            ratio = (statistics.median(per_input_us(node, key))
                     / statistics.median(per_input_us(relay, key)))
            best = min(per_input_us(node, key)) / min(per_input_us(relay, key))
            print(f'{executor_kind}: node / relay, {what}: {ratio:.2f} (medians), '
                  f'{best:.2f} (minima): '
                  f'{"MET" if ratio <= GOAL[executor_kind] else "NOT MET"} '
                  f'(goal <= {GOAL[executor_kind]:g}x the relay)')
    costs = in_process_costs(args.messages)
    print('in-process cost of the parts of the node callback (us per input, min of 3): '
          + ', '.join(f'{k} {v:.1f}' for k, v in costs.items()))
    for executor_kind in args.executors:
        node_us = statistics.median(per_input_us(results[(executor_kind, 'node')],
                                                 'thread_cpu'))
        line = (f'{executor_kind}: session.add in-process is {costs["session.add"] / node_us:.0%}'
                f" of the node's executor thread CPU per input ({node_us:.1f} us)")
        if (executor_kind, 'stub') in results:
            stub_us = statistics.median(per_input_us(results[(executor_kind, 'stub')],
                                                     'thread_cpu'))
            line += (f'; the node minus its stubbed twin (no filter, {stub_us:.1f} us): '
                     f'{node_us - stub_us:.1f} us = {(node_us - stub_us) / node_us:.0%}')
        print(line)


if __name__ == '__main__':
    main()
