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

"""The demo's client: collect the pipeline's topics into a plain record, in or across processes."""

from dataclasses import dataclass, field
import time
from typing import Callable, Optional, Union

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import Illuminance, JointState
from std_msgs.msg import Float64MultiArray

from tskf_ros.messages import conversions


@dataclass
class Record:
    """What the demo saw: arrays keyed by stamp (ns)."""

    power: dict = field(default_factory=dict)       # stamp -> mW
    truth: dict = field(default_factory=dict)       # stamp -> rad
    predicted: dict = field(default_factory=dict)   # stamp -> (x, P)
    corrected: dict = field(default_factory=dict)


class Collector(Node):
    """Subscribe to received_power, true_angle and the estimates; keep them in a Record."""

    def __init__(self, *, context: Optional[Context] = None) -> None:
        super().__init__('demo_collector', context=context)
        self.record = Record()
        deep = QoSProfile(depth=10_000)
        # best effort to match the sensor-data publisher, but a deep queue: the demo process
        # also spins other nodes and must not drop what DDS delivered
        lossless = QoSProfile(depth=10_000, reliability=qos_profile_sensor_data.reliability)
        self.create_subscription(Illuminance, 'received_power', self._on_power, lossless)
        self.create_subscription(JointState, 'true_angle', self._on_truth, deep)
        self.create_subscription(Float64MultiArray, 'estimate/predicted',
                                 self._on_estimate(self.record.predicted), deep)
        self.create_subscription(Float64MultiArray, 'estimate/corrected',
                                 self._on_estimate(self.record.corrected), deep)

    def _on_power(self, msg: Illuminance) -> None:
        t, p, _ = conversions.msg_to_power(msg)
        self.record.power[t] = p

    def _on_truth(self, msg: JointState) -> None:
        t, a = conversions.msg_to_angle(msg)
        self.record.truth[t] = float(a[0])

    @staticmethod
    def _on_estimate(store: dict) -> Callable:
        def callback(msg: Float64MultiArray) -> None:
            e = conversions.msg_to_state_estimate(msg)
            store[e.stamp_ns] = (float(e.x[0]), float(e.P[0, 0]))
        return callback

    def done(self, samples: int) -> bool:
        """All truth seen and the estimator has caught up with the last published power."""
        r = self.record
        if len(r.truth) < samples or len(r.power) < 2:
            return False
        before, last = sorted(r.power)[-2:]
        return (max(r.predicted, default=-1) >= last
                and max(r.corrected, default=-1) >= before)

    def peers_ready(self) -> bool:
        """Tell whether the estimator's outputs are discovered (so its input is subscribed)."""
        return (self.count_publishers('estimate/predicted') > 0
                and self.count_publishers('estimate/corrected') > 0)


def spin_until(executor: SingleThreadedExecutor, condition: Callable[[], bool],
               timeout: float) -> bool:
    """Spin until condition() or timeout seconds; return whether it held."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.02)
    return True


def wait_for(executor: SingleThreadedExecutor, condition: Callable[[], bool],
             what: Union[str, Callable[[], str]], timeout: float = 60.0) -> None:
    """
    Spin until condition() holds; raise TimeoutError saying what never happened.

    The timeout bounds a wait on DDS (discovery, matching, delivery); it is never an
    assertion about timing, so it is generous: it costs nothing when things work.  `what`
    may be a callable, called only on failure (to report the state reached).
    """
    if not spin_until(executor, condition, timeout):
        raise TimeoutError(f'timed out after {timeout:g} s waiting for '
                           f'{what() if callable(what) else what}')


def run_in_process(*, duration: float = 300.0, time_factor: float = 30.0, seed: int = 0,
                   rate: float = 1.0, timeout: float = 120.0,
                   simulator_parameters: Optional[dict] = None,
                   estimator_parameters: Optional[dict] = None) -> Record:
    """Run the demo's pipeline in one process: simulator, estimator, collector, one executor."""
    from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
    from tskf_ros.nodes.timescale_estimator import TimescaleEstimator

    context = Context()
    rclpy.init(context=context)
    nodes = []
    executor = SingleThreadedExecutor(context=context)
    try:
        collector = Collector(context=context)
        estimator = TimescaleEstimator(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in (estimator_parameters or {}).items()],
            cli_args=['--ros-args', '-r', 'measurement:=received_power'])
        sim = {'duration': float(duration), 'time_factor': float(time_factor),
               'seed': int(seed), 'rate': float(rate), 'start_time': 1.0,
               'wait_for_subscribers': 2, **(simulator_parameters or {})}
        simulator = PowerMeterSimulator(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in sim.items()])
        nodes = [collector, estimator, simulator]
        for node in nodes:
            executor.add_node(node)
        samples = int(round(duration * rate))
        if not spin_until(executor, lambda: collector.done(samples), timeout):
            raise TimeoutError(f'the pipeline did not finish {samples} samples in {timeout} s')
        return collector.record
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        context.try_shutdown()


def collect(samples: int, *, timeout: float, on_ready: Callable[[], None],
            discovery_timeout: float = 30.0) -> Record:
    """Collect from nodes running elsewhere: call on_ready() once the estimator is seen."""
    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    collector = Collector(context=context)
    executor.add_node(collector)
    try:
        if not spin_until(executor, collector.peers_ready, discovery_timeout):
            raise TimeoutError('the estimator process was not discovered')
        on_ready()
        if not spin_until(executor, lambda: collector.done(samples), timeout):
            raise TimeoutError(f'the pipeline did not finish {samples} samples in {timeout} s '
                               f'(saw {len(collector.record.truth)} truth samples)')
        return collector.record
    finally:
        executor.shutdown()
        collector.destroy_node()
        context.try_shutdown()


def arrays(store: dict) -> tuple[np.ndarray, np.ndarray]:
    """Sorted (stamps ns, values) of a stamp -> value (or (x, P)) store."""
    keys = np.array(sorted(store), dtype=np.int64)
    vals = [store[k] for k in keys]
    if vals and isinstance(vals[0], tuple):
        return keys, np.array([v[0] for v in vals])
    return keys, np.array(vals, dtype=float)
