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

"""The demo's client for the LED alignment loop: collect the truth, commands and diagnostics."""

from dataclasses import dataclass, field
import threading
from typing import Callable, Optional

from diagnostic_msgs.msg import DiagnosticArray
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Illuminance, JointState
from std_msgs.msg import Float64MultiArray

from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import COMMAND_TOPIC
from tskf_ros.messages.qos import sensor_input_qos
from tskf_ros.tools.demo_collector import spin_until


@dataclass
class AlignmentRecord:
    """What the monitor saw (angles in degrees)."""

    phi: dict = field(default_factory=dict)          # stamp ns -> true angle of incidence
    intensity: dict = field(default_factory=dict)    # stamp ns -> V
    commands: int = 0
    diagnostics: dict = field(default_factory=dict)  # the alignment node's last status


class AlignmentMonitor(Node):
    """Subscribe to the loop's topics (in `namespace`); keep them in an AlignmentRecord."""

    def __init__(self, *, context: Optional[Context] = None, namespace: str = '') -> None:
        super().__init__('alignment_monitor', context=context, namespace=namespace or None)
        self.record = AlignmentRecord()
        self.create_subscription(JointState, 'true_angle', self._on_truth,
                                 QoSProfile(depth=10_000))
        # best effort as the simulator publishes, but deep: a short queue drops under load
        self.create_subscription(Illuminance, 'intensity', self._on_intensity,
                                 sensor_input_qos(10_000))
        self.create_subscription(Float64MultiArray, COMMAND_TOPIC, self._on_command,
                                 QoSProfile(depth=10_000))
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)

    def _on_truth(self, msg: JointState) -> None:
        t, angles = conversions.msg_to_led_truth(msg)
        self.record.phi[t] = float(angles['incidence'])

    def _on_intensity(self, msg: Illuminance) -> None:
        t, v, _ = conversions.msg_to_intensity(msg)
        self.record.intensity[t] = v

    def _on_command(self, msg: Float64MultiArray) -> None:
        self.record.commands += 1

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        statuses = conversions.msg_to_diagnostics(msg)
        aligner = [name for name in statuses if name.endswith(': aligner')]
        if aligner:     # the aligner's task and its time scale's, in one dict
            node = aligner[0][:-len('aligner')]
            self.record.diagnostics = {**statuses.get(node + 'time scale', {}),
                                       **statuses[aligner[0]]}

    def peers_ready(self) -> bool:
        """Tell whether the alignment node's command publisher is discovered."""
        return self.count_publishers(COMMAND_TOPIC) > 0


def monitor(samples: int, *, namespace: str, timeout: float, on_ready: Callable[[], None],
            discovery_timeout: float = 30.0,
            stop: Optional[threading.Event] = None) -> AlignmentRecord:
    """
    Collect the loop in its own context: call on_ready() once the alignment node is seen.

    stop (set from another thread: the demo's Ctrl-C) ends every wait at once and returns
    what was collected, so that the thread ends before the process does.
    """
    stop = stop or threading.Event()
    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    node = AlignmentMonitor(context=context, namespace=namespace)
    executor.add_node(node)
    try:
        if not spin_until(executor, lambda: stop.is_set() or node.peers_ready(),
                          discovery_timeout):
            raise TimeoutError('the alignment process was not discovered')
        if stop.is_set():
            return node.record
        on_ready()
        if not spin_until(executor, lambda: stop.is_set() or len(node.record.phi) >= samples,
                          timeout):
            raise TimeoutError(f'the alignment loop did not finish {samples} samples in '
                               f'{timeout} s (saw {len(node.record.phi)})')
        # the answer to the last sample, and a diagnostics report after it
        spin_until(executor, lambda: stop.is_set() or (
            node.record.commands >= len(node.record.intensity)
            and node.record.diagnostics.get('Samples received') == str(
                len(node.record.intensity))), 3.0)
        return node.record
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
