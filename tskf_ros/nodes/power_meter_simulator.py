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

"""The power_meter_simulator node: the intermittent OWC link of Cai et al. IV-A/B."""

from dataclasses import dataclass, replace
from typing import Optional

from rcl_interfaces.msg import SetParametersResult

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import POWER_TOPIC
from tskf_ros.nodes.node_base import link_config, LinkSimulatorNode, MAX_BATCH
from tskf_ros.nodes.node_runner import run_node
from tskf_ros.owc.vibrating_link import OwcLink, OwcLinkConfig, OwcLinkError, Samples

NODE_NAME = 'power_meter_simulator'


@dataclass(frozen=True)
class SimulatorConfig:
    """The node's settings, read once: the link and how it is played out."""

    link: OwcLinkConfig
    time_factor: float
    duration: float
    start_time: float
    publish_invalid: bool
    wait_for_subscribers: int
    frame_id: str
    angle_name: str


class PowerMeterSimulator(LinkSimulatorNode):
    """Publish simulated received power and the true angle at `rate` (times time_factor)."""

    SCHEMA = NODE_NAME
    SENSOR_TOPIC = POWER_TOPIC

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.link = OwcLink(self.config.link)
        self.add_on_set_parameters_callback(self._validate)
        link = self.config.link
        self.total = int(round(self.config.duration * link.rate)) or None
        self.published = 0
        period = max(1.0 / (link.rate * self.config.time_factor), 1e-3)
        self.timer = self.create_timer(period, self._tick)
        self.start_diagnostics(link.rate * self.config.time_factor, lambda: self.published)
        self.get_logger().info(
            f'simulating the OWC link at {link.rate:g} Hz x {self.config.time_factor:g}, '
            f'seed {link.seed}, blockage {link.blockage}'
            + (f', {self.total} samples' if self.total else ''))

    def _read(self, values: dict) -> SimulatorConfig:
        link = link_config(OwcLinkConfig, values, OwcLinkError)
        return SimulatorConfig(link, values['time_factor'], values['duration'],
                               values['start_time'], values['publish_invalid'],
                               values['wait_for_subscribers'], values['frame_id'],
                               values['angle_name'])

    def _validate(self, changes: list) -> SetParametersResult:
        """Only publish_invalid changes at run time; the seeded stream is fixed at start."""
        for p in changes:
            if p.name == 'publish_invalid':
                if not isinstance(p.value, bool):
                    return SetParametersResult(successful=False,
                                               reason='publish_invalid must be a bool')
                self.config = replace(self.config, publish_invalid=p.value)
        return SetParametersResult(successful=True)

    def _tick(self) -> None:
        now = self.get_clock().now().nanoseconds
        if not self.started(now):
            return
        link, factor = self.config.link, self.config.time_factor
        due = int((now - self.start_ns) / NS * factor * link.rate) + 1
        if self.total is not None:
            due = min(due, self.total)
        n = min(due - self.published, MAX_BATCH)
        if n > 0:
            self.publish_samples(self.link.generate(n))
        if self.total is not None and self.published >= self.total:
            self.timer.cancel()
            self.get_logger().info(f'published all {self.total} samples; stopping')

    def publish_samples(self, s: Samples) -> None:
        """
        Publish a batch of samples: the power unless it is a gap, then the truth always.

        The power goes first, so that a client that stops at the last true angle has had
        the last reading sent before it (the demo's collector stopped one reading short).
        """
        cfg = self.config
        var = cfg.link.noise_std ** 2
        for i in range(len(s)):
            stamp = self.stamp0_ns + int(round(int(s.index[i]) * NS / cfg.link.rate))
            if not s.blocked[i] and (s.reading[i] > 0 or cfg.publish_invalid):
                self.sensor_pub.publish(conversions.power_to_msg(stamp, s.reading[i], var,
                                                                 frame_id=cfg.frame_id))
            self.truth_pub.publish(conversions.angle_to_msg(stamp, [s.theta[i]],
                                                            [cfg.angle_name]))
        self.published += len(s)


DESCRIPTION = ('Simulated power meter of the vibration-induced '
               'intermittent OWC link (Cai et al. IV). Parameters: --ros-args --params-file '
               'config/power_meter_simulator.yaml or -p name:=value')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(PowerMeterSimulator, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(OwcLinkError,), args=args)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
