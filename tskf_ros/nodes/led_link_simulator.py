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

"""The led_link_simulator node: the LED link of Solanki et al. 2018 Section V, base commanded."""

from dataclasses import dataclass, replace
import math
from typing import Optional, Union

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from std_msgs.msg import Float64MultiArray

from tskf_ros import led
from tskf_ros.core.units import NS
from tskf_ros.led.led_link import LedLink, LedLinkConfig, LedLinkError, LedSample, sample_offset_ns
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLink, PanTiltLinkConfig, PanTiltSample
from tskf_ros.led.two_axis.radial_response import RadialResponse
from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import COMMAND_TOPIC, INPUT_TOPIC
from tskf_ros.messages.pan_tilt_interface import check_joints
from tskf_ros.messages.pan_tilt_messages import pan_tilt_truth_to_msg
from tskf_ros.messages.parameter_schema import ParameterError
from tskf_ros.messages.qos import DEFAULT_DEPTH
from tskf_ros.nodes.node_base import link_config, LinkSimulatorNode, MAX_BATCH
from tskf_ros.nodes.node_runner import run_node

NODE_NAME = 'led_link_simulator'


@dataclass(frozen=True)
class LedSimulatorConfig:
    """The node's settings, read once: the link and how it is played out."""

    link: LedLinkConfig
    time_factor: float
    lockstep: bool
    command_timeout: float
    duration: float
    start_time: float
    wait_for_subscribers: int
    frame_id: str
    beam_blocked: bool = False
    pan_tilt: Optional[PanTiltLinkConfig] = None     # axes 2: the two-axis link
    joints: tuple[str, str] = ('pan', 'tilt')


def pan_tilt_link_config(link: LedLinkConfig, values: dict) -> PanTiltLinkConfig:
    """Return the two-axis link of the shared parameters; LedLinkError (one line) if none."""
    if link.blockage == 'gilbert_elliott':
        raise LedLinkError('axes 2 takes blockage none or bernoulli (the two-axis link drops '
                           'samples independently), got gilbert_elliott')
    if not abs(link.phi0) < 90.0:
        raise LedLinkError(f"axes 2: phi0, the source's angle off the boresight at sample 0, "
                           f'must be within +-90 deg, got {link.phi0:g}')
    if link.max_speed > 0:
        raise LedLinkError('axes 2: the mount reaches each command within a sample; '
                           f'max_speed must be 0, got {link.max_speed:g}')
    try:
        return PanTiltLinkConfig(
            beta=link.beta, dt=link.dt, noise=link.noise,
            q_sys=(link.intensity_walk ** 2, link.angle_noise ** 2),
            max_intensity=link.max_intensity, offset0=abs(link.phi0),
            elevation0=values['pan_tilt.elevation0'], jitter=values['pan_tilt.jitter'],
            dropout=link.drop_probability if link.blockage == 'bernoulli' else 0.0)
    except led.AlignmentError as exc:
        raise LedLinkError(f'bad simulator parameters: {exc}') from None


class LedLinkSimulator(LinkSimulatorNode):
    """Publish simulated intensity and truth; turn the base as commanded."""

    SCHEMA = NODE_NAME
    SENSOR_TOPIC = INPUT_TOPIC

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        cfg = self.config
        self.link: Union[LedLink, PanTiltLink] = (
            LedLink(cfg.link) if cfg.pan_tilt is None else PanTiltLink(
                cfg.pan_tilt, runs=1, seed=cfg.link.seed,
                response=RadialResponse(cfg.link.response())))
        self.link.obstructed = self.config.beam_blocked
        self.add_on_set_parameters_callback(self._validate)
        link = self.config.link
        # forward_command_controller subscribes with the system-default QoS (reliable, 10)
        self.command_sub = self.create_subscription(Float64MultiArray, COMMAND_TOPIC,
                                                    self._on_command, DEFAULT_DEPTH)
        self.total = int(round(self.config.duration / link.dt)) or None
        self.commands = 0
        self.bad_commands = 0
        self.timeouts = 0
        self._waiting_since: Optional[int] = None    # lockstep: a delivered sample's time
        self._answered = True
        self._finished = False
        factor = self.config.time_factor
        period = max(link.dt / factor, 1e-3) if factor > 0 else 0.01
        self.timer = self.create_timer(period, self._tick)
        lockstep = self.config.lockstep or factor <= 0
        self.start_diagnostics(0.0 if lockstep else factor / link.dt, lambda: self.taken)
        self.get_logger().info(
            f'simulating the LED link: beta {link.beta:g} deg/s, noise {link.noise:g} V, '
            f'dt {link.dt:g} s x {factor:g}{" (lockstep)" if self.config.lockstep else ""}, '
            f'seed {link.seed}, blockage {link.blockage}'
            + ('' if cfg.pan_tilt is None else
               f'; a pan-tilt mount ({cfg.joints[0]}, {cfg.joints[1]}), tilt '
               f'{cfg.pan_tilt.elevation0:g} deg at the start')
            + (f', {self.total} samples' if self.total else ''))

    @property
    def taken(self) -> int:
        """Return the number of samples taken so far (published or dropped)."""
        return self.link.count

    def _read(self, values: dict) -> LedSimulatorConfig:
        link = link_config(LedLinkConfig, values, LedLinkError)
        try:
            joints = check_joints(values)
        except ParameterError as exc:
            raise LedLinkError(str(exc)) from None
        pan_tilt = pan_tilt_link_config(link, values) if values['axes'] == 2 else None
        return LedSimulatorConfig(link, values['time_factor'], values['lockstep'],
                                  values['command_timeout'], values['duration'],
                                  values['start_time'], values['wait_for_subscribers'],
                                  values['frame_id'], values['beam_blocked'], pan_tilt,
                                  joints)

    def _validate(self, changes: list) -> SetParametersResult:
        """Only beam_blocked changes at run time; the seeded stream is fixed at start."""
        for p in changes:
            if p.name == 'beam_blocked':
                if not isinstance(p.value, bool):
                    return SetParametersResult(successful=False,
                                               reason='beam_blocked must be a bool')
                if p.value != self.config.beam_blocked:
                    self.get_logger().info('beam blocked: the photodiode sees no light'
                                           if p.value else 'beam unblocked')
                self.config = replace(self.config, beam_blocked=p.value)
                self.link.obstructed = p.value
        return SetParametersResult(successful=True)

    # -- the loop ---------------------------------------------------------------------------

    def _on_command(self, msg: Float64MultiArray) -> None:
        angles = conversions.msg_to_base_command(msg)
        n = 1 if self.config.pan_tilt is None else 2
        if angles.size != n or not np.all(np.isfinite(angles)):
            self.bad_commands += 1
            self.get_logger().warning(
                f'base command ignored: expected {("one", "two")[n - 1]} finite joint '
                f'position{"s" if n > 1 else ""} (rad), got {list(msg.data)}',
                throttle_duration_sec=1.0)
            return
        if isinstance(self.link, PanTiltLink):
            self.link.command(angles)
        else:
            self.link.command(float(angles[0]))
        self.commands += 1
        self._answered = True
        if self.start_ns is not None:
            self._advance(self.get_clock().now().nanoseconds)

    def _tick(self) -> None:
        now = self.get_clock().now().nanoseconds
        if self.started(now):
            self._advance(now)

    def ready(self) -> bool:
        """Sample 0 waits for the subscribers and, in lockstep, a command publisher."""
        cfg = self.config
        return super().ready() and not (
            cfg.lockstep and cfg.wait_for_subscribers
            and self.count_publishers(self.command_sub.topic_name) < 1)

    def _advance(self, now: int) -> None:
        """Take every sample that is due and, in lockstep, answered; stop at the end."""
        cfg = self.config
        for _ in range(MAX_BATCH):
            if self._finished:
                return
            if self.total is not None and self.taken >= self.total:
                self._finished = True
                self.timer.cancel()
                self.get_logger().info(f'took all {self.total} samples; stopping')
                return
            if self._waiting_since is not None:
                if not self._answered:
                    if now - self._waiting_since < cfg.command_timeout * NS:
                        return
                    self.timeouts += 1
                    self.get_logger().warning(
                        f'no base command within {cfg.command_timeout:g} s of sample '
                        f'{self.taken - 1}; going on without it', throttle_duration_sec=1.0)
                self._waiting_since = None
            if cfg.time_factor > 0:
                elapsed = (now - self.start_ns) / NS * cfg.time_factor
                if self.taken > elapsed / cfg.link.dt:
                    return
            self._publish(self.link.sample(), now)

    def _publish(self, s: Union[LedSample, PanTiltSample], now: int) -> None:
        """Publish one sample: the truth always, the intensity unless it was dropped."""
        cfg = self.config
        if isinstance(s, PanTiltSample):    # its own time: k dt, or jittered (pan_tilt.jitter)
            stamp = self.stamp0_ns + int(round(s.t * NS))
            self.truth_pub.publish(pan_tilt_truth_to_msg(stamp, s.joints[0], s.source[0],
                                                         float(s.theta[0]), cfg.joints))
            dropped, reading = bool(s.missing[0]), float(s.reading[0])
        else:
            stamp = self.stamp0_ns + sample_offset_ns(s.index, cfg.link.dt)
            self.truth_pub.publish(conversions.led_truth_to_msg(stamp, s.phi, s.base,
                                                                s.bearing))
            dropped, reading = s.blocked, s.reading
        if dropped or not math.isfinite(reading):
            return
        if cfg.lockstep:
            self._answered = False
            self._waiting_since = now
        self.sensor_pub.publish(conversions.intensity_to_msg(
            stamp, reading, cfg.link.noise ** 2, frame_id=cfg.frame_id))


DESCRIPTION = ('Simulated LED link with a commanded rotating receiver '
               'base (Solanki et al. V). Parameters: --ros-args --params-file '
               'config/led_link_simulator.yaml or -p name:=value')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(LedLinkSimulator, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(LedLinkError,), args=args)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
