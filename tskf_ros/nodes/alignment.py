"""The alignment node: LED active alignment (Solanki et al. 2018) on stamped intensities."""

from typing import Optional

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistWithCovarianceStamped
from sensor_msgs.msg import Illuminance, JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool

from tskf_ros import led
from tskf_ros.led.alignment_diagnostics import status_line
from tskf_ros.led.alignment_session import AlignmentSession, AlignOutcome
from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import (COMMAND_TYPE, diagnostics_message,
                                                   INPUT_TOPIC, NODE_NAME, NodeConfig,
                                                   outcome_messages, output_qos, OUTPUT_TOPICS,
                                                   OUTPUT_TYPES, parameters_to_config)
from tskf_ros.messages.conversions import ESTIMATE_TYPE, STATES_TYPE
from tskf_ros.messages.qos import sensor_input_qos
from tskf_ros.nodes.node_base import ReconfigurableNode
from tskf_ros.nodes.node_runner import run_node


class Alignment(ReconfigurableNode):
    """Node wrapping AlignmentSession: intensity in, base commands, estimates, diagnostics out."""

    SCHEMA = NODE_NAME
    SESSION = AlignmentSession
    CONFIG_ERRORS = (led.AlignmentError, KeyError, TypeError, ValueError)

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        qos_in = sensor_input_qos(self.config.queue_depth)
        self.sub = self.create_subscription(Illuminance, INPUT_TOPIC, self._on_intensity,
                                            qos_in)
        types = {COMMAND_TYPE: Float64MultiArray, ESTIMATE_TYPE: TwistWithCovarianceStamped,
                 STATES_TYPE: JointState}
        self.pubs = {
            key: self.create_publisher(types[OUTPUT_TYPES[key]], topic,
                                       output_qos(self.config, key))
            for key, topic in OUTPUT_TOPICS.items()}
        self.start_diagnostics()
        self.watch_clock_jumps()
        self.start_services()
        # ~/enable (std_srvs/srv/SetBool): false pauses the loop (no step, no command)
        self.enabled = True
        self.paused = 0
        self.enable_service = self.create_service(SetBool, '~/enable', self._on_enable)
        cfg = self.config.session
        self.get_logger().info(
            f'aligning with {cfg.algorithm}'
            + (' and the time-scale LQG controller' if cfg.algorithm == 'ekf'
               and cfg.controller == 'lqg' else
               f' (G = {cfg.gain:g}, {len(cfg.scan)} scan angles)'
               if cfg.algorithm == 'ekf' else f' (gamma = {cfg.gamma:g} deg)')
            + f', base starting at {cfg.base_initial:g} deg')

    # -- parameters -----------------------------------------------------------------------

    def make_config(self, values: dict) -> NodeConfig:
        """Build the node's config; raises with the reason if it makes no working aligner."""
        return parameters_to_config(values)

    def reconfigure(self, config: NodeConfig) -> str:
        """Switch the session to a validated config; return what it did."""
        return self.session.reconfigure(config.session)

    # -- data -----------------------------------------------------------------------------

    def _on_intensity(self, msg: Illuminance) -> None:
        stamp_ns, volts, _ = conversions.msg_to_intensity(msg)
        now_ns = self.get_clock().now().nanoseconds
        if not self.enabled:
            self.paused += 1
            self.session.skip(stamp_ns, now_ns)      # counted in diagnostics, not used
            return
        out = self.session.add(stamp_ns, volts, now_ns=now_ns)
        self._report(out)
        self._publish(out)

    def _report(self, out: AlignOutcome) -> None:
        log = self.get_logger()
        if out.status == 'rejected':
            log.warning(f'sample dropped ({out.reason}): {out.message}')
        elif out.status == 'missing':
            log.warning(f'sample at {out.stamp_ns / 1e9:.3f} s treated as missing '
                        f'({out.reason}): {out.message}', throttle_duration_sec=1.0)
        elif out.status == 'reset':
            log.warning(f'aligner restarted ({out.reason}): {out.message}')

    def _publish(self, out: AlignOutcome) -> None:
        for key, msg in outcome_messages(out, self.config):
            self.pubs[key].publish(msg)

    def restart(self, why: str, reason: str = 'clock_jump') -> None:
        """Restart the aligner, saying why (nothing to do before a sample)."""
        if self.session.last_ns is None:
            return
        self.session.reset(reason)
        self.get_logger().warning(f'aligner restarted: {why}')

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
        return status_line(s.stats, rate, s.base, s.paused,
                           None if s.ekf is None else s.ekf.x[0])

    def diagnostics_message(self, stamp_ns: int) -> DiagnosticArray:
        """Return the session's counters as a /diagnostics message."""
        return diagnostics_message(self.session, self.config, stamp_ns,
                                   node_name=self.get_name())


DESCRIPTION = ('LED active alignment (Solanki et al.): scanning EKF, hill-climbing or '
               'three-point averaging on the intensity, commanding a rotating base. '
               'Parameters: --ros-args --params-file config/alignment.yaml or -p name:=value')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(Alignment, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(led.AlignmentError,), args=args)


if __name__ == '__main__':
    main()
