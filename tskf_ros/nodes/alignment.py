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

"""The alignment node: LED active alignment (Solanki et al. 2018) on stamped intensities."""

from typing import Any, Callable, Optional, TYPE_CHECKING, Union

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks
from sensor_msgs.msg import Illuminance
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger

from tskf_ros import led
from tskf_ros.led.alignment_config import AlignmentConfig
from tskf_ros.led.alignment_diagnostics import status_line
from tskf_ros.led.alignment_session import AlignmentSession, AlignOutcome
from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import (diagnostics_message, INPUT_TOPIC,
                                                   NODE_NAME, NodeConfig, outcome_messages,
                                                   output_qos, OUTPUT_TOPICS,
                                                   parameters_to_config, pat_state_message,
                                                   pat_state_qos, PAT_STATE_TOPIC)
from tskf_ros.messages.pan_tilt_messages import check_joints
from tskf_ros.messages.qos import sensor_input_qos
from tskf_ros.nodes.node_base import diagnostic_name, ReconfigurableNode
from tskf_ros.nodes.node_runner import run_node

if TYPE_CHECKING:       # the two-axis modules: imported for axes 2 only
    from tskf_ros.led.pan_tilt_stream import PanTiltStep, PanTiltStream


def new_session(config: Any) -> Union[AlignmentSession, 'PanTiltStream']:
    """Return the session of a config: the one-axis session or the two-axis stream (axes 2)."""
    if isinstance(config, AlignmentConfig):
        return AlignmentSession(config)
    from tskf_ros.led.pan_tilt_stream import PanTiltStream
    return PanTiltStream(config)


class Alignment(ReconfigurableNode):
    """
    Node wrapping the alignment session: intensity in, commands, estimates, diagnostics out.

    One node for one and two axes (`axes`): the two share the input, the topics, the
    services, the supervisor's parameters and the diagnostics, so a second node would
    repeat all of it; only the session and the messages' lengths differ.
    """

    SCHEMA = NODE_NAME
    SESSION = staticmethod(new_session)
    CONFIG_ERRORS = (led.AlignmentError, KeyError, TypeError, ValueError)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        qos_in = sensor_input_qos(self.config.queue_depth)
        self.sub = self.create_subscription(
            Illuminance, INPUT_TOPIC, self._on_intensity, qos_in,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost))
        # every output (the estimates and the command) is a std_msgs/msg/Float64MultiArray
        self.pubs = {key: self.create_publisher(Float64MultiArray, topic,
                                                output_qos(self.config, key))
                     for key, topic in OUTPUT_TOPICS.items()}
        # the supervisor's state, latched: published at start and on each transition
        self.pat_pub = self.create_publisher(String, PAT_STATE_TOPIC, pat_state_qos())
        self.start_diagnostics()
        self.watch_clock_jumps()
        self.start_services()
        # ~/enable (std_srvs/srv/SetBool): false pauses the loop (no step, no command)
        self.enabled = True
        self.paused = 0
        self.enable_service = self.create_service(SetBool, '~/enable', self._on_enable)
        # ~/acquire (std_srvs/srv/Trigger): force a new cold search (pat.enabled)
        self.acquire_service = self.create_service(Trigger, '~/acquire', self._on_acquire)
        self.two_axes = not isinstance(self.session, AlignmentSession)
        self.joints = check_joints(self.parameter_values())
        # the two-axis outcome's messages (axes is read-only: the session's kind stays)
        self.pan_tilt_messages: Optional[Callable[..., list]] = None
        cfg = self.config.session
        if self.two_axes:
            from tskf_ros.messages.pan_tilt_interface import pan_tilt_outcome_messages
            self.pan_tilt_messages = pan_tilt_outcome_messages
            s = cfg.session
            self._log_start(
                f'aligning a pan-tilt mount ({self.joints[0]}, {self.joints[1]}) with '
                f'{s.method}, starting at [{s.joints0[0]:g}, {s.joints0[1]:g}] deg'
                + ('' if s.method == 'conical_ekf' else f', starting {s.start}'))
            return
        self._log_start(
            f'aligning with {cfg.algorithm}'
            + (' and the time-scale LQG controller' if cfg.algorithm == 'ekf'
               and cfg.controller == 'lqg' else
               f' (G = {cfg.gain:g}, {len(cfg.scan)} scan angles)'
               if cfg.algorithm == 'ekf' else f' (gamma = {cfg.gamma:g} deg)')
            + f', base starting at {cfg.base_initial:g} deg'
            + (f'; pointing supervisor on, starting {cfg.pat.start}' if cfg.pat.enabled
               else '; no pointing supervisor'))

    def _log_start(self, line: str) -> None:
        """Log the start line and the supervisor's first state once the node spins."""
        def log() -> None:
            self.get_logger().info(line)
            self._report_transitions()
        self.when_spinning(log)

    # -- parameters -----------------------------------------------------------------------

    def make_config(self, values: dict) -> NodeConfig:
        """Build the node's config; raises with the reason if it makes no working aligner."""
        return parameters_to_config(values)

    def reconfigure(self, config: NodeConfig) -> str:
        """Switch the session to a validated config; return what it did."""
        message = self.session.reconfigure(config.session)
        self._report_transitions()
        return message

    # -- data -----------------------------------------------------------------------------

    def _on_intensity(self, msg: Illuminance) -> None:
        stamp_ns, volts, _ = conversions.msg_to_intensity(msg)
        now_ns = self.get_clock().now().nanoseconds
        if not self.enabled:
            self.paused += 1
            self.session.skip(stamp_ns, now_ns)      # counted in diagnostics, not used
            return
        out = self.session.add(stamp_ns, volts, now_ns=now_ns)
        self._report(out.outcome if self.two_axes else out)
        self._publish(out)
        if self.session.pointing.pending:
            self._report_transitions()

    def _on_lost(self, info: QoSMessageLostInfo) -> None:
        # the middleware's count of intensities lost in transport (diagnostics: aligner)
        self.session.stats.messages_lost = info.total_count

    def _report_transitions(self) -> None:
        """Log each state transition once (a loss at WARN) and publish it on pat_state."""
        for t in self.session.take_transitions():
            at = '' if t.stamp_ns is None else f' at {t.stamp_ns / 1e9:.3f} s'
            text = (f'pointing: {t.old} -> {t.new} ({t.reason}){at}' if t.old else
                    f'pointing: {t.new} ({t.reason})')
            if t.new == 'lost':
                self.get_logger().warning(text)
            elif t.old or t.new != 'disabled':     # (the start line says 'no supervisor')
                self.get_logger().info(text)
            self.pat_pub.publish(pat_state_message(t))

    def _report(self, out: Any) -> None:
        log = self.get_logger()
        supervised = self.session.pat_state != 'disabled'
        if out.status == 'rejected':
            log.warning(f'sample dropped ({out.reason}): {out.message}')
        elif out.status == 'missing' and not (out.reason == 'negative' and supervised):
            # (the supervisor takes a negative reading as the dark it is: no warning)
            log.warning(f'sample at {out.stamp_ns / 1e9:.3f} s treated as missing '
                        f'({out.reason}): {out.message}', throttle_duration_sec=1.0)
        elif out.status == 'reset':
            log.warning(f'aligner restarted ({out.reason}): {out.message}')

    def _publish(self, out: Union[AlignOutcome, 'PanTiltStep']) -> None:
        msgs = (self.pan_tilt_messages(out, self.joints) if self.pan_tilt_messages is not None
                else outcome_messages(out, self.config))
        for key, msg in msgs:
            self.pubs[key].publish(msg)

    def restart(self, why: str, reason: str = 'clock_jump') -> None:
        """Restart the aligner, saying why (nothing to do before a sample)."""
        if self.session.last_ns is None:
            return
        self.session.reset(reason)
        self.get_logger().warning(f'aligner restarted: {why}')
        self._report_transitions()

    def _on_acquire(self, request: Trigger.Request,
                    response: Trigger.Response) -> Trigger.Response:
        if not self.session.acquire():
            response.success = False
            response.message = 'no pointing supervisor (pat.enabled is false): nothing to do'
            return response
        self._report_transitions()
        response.success = True
        response.message = 'searching' + (' (paused: ~/enable is false)'
                                          if not self.enabled else '')
        return response

    def _on_enable(self, request: SetBool.Request,
                   response: SetBool.Response) -> SetBool.Response:
        was, self.enabled = self.enabled, bool(request.data)
        self.session.paused = not self.enabled
        if self.enabled and not was:
            # the EKF predicts over the pause (mu = elapsed / dt): nothing to reset
            self.get_logger().info(f'alignment resumed after {self.paused} paused samples')
        elif was and not self.enabled:
            self.get_logger().info('alignment paused: no steps, no commands')
        response.success = True
        response.message = 'enabled' if self.enabled else 'paused'
        return response

    def status_line(self, rate: float) -> str:
        """Return the INFO status line: rate, gaps, last command and estimate, restarts."""
        s = self.session
        if self.two_axes:
            e = s.session.estimate()
            pan, tilt = s.joints
            return status_line(s.stats, rate, pan, s.paused, None if e is None else e.x[:3],
                               s.pat_state, tilt)
        return status_line(s.stats, rate, s.base, s.paused,
                           None if s.ekf is None else s.ekf.x[0], s.pat_state)

    def diagnostics_message(self, stamp_ns: int) -> DiagnosticArray:
        """Return the session's counters as a /diagnostics message."""
        return diagnostics_message(self.session, self.config, stamp_ns,
                                   node_name=diagnostic_name(self))


DESCRIPTION = ('LED active alignment (Solanki et al.): scanning EKF, hill-climbing or '
               'three-point averaging on the intensity, commanding a rotating base, inside '
               'an acquiring / tracking / lost supervisor (pat.enabled). '
               'Parameters: --ros-args --params-file config/alignment.yaml or -p name:=value')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(Alignment, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(led.AlignmentError,), args=args)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
