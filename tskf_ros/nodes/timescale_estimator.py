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

"""The timescale_estimator node: the time-scale Kalman filter of Cai et al. on a stream."""

from typing import Any, Optional, TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped
from rclpy.event_handler import QoSMessageLostInfo, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy
from std_msgs.msg import Float64MultiArray

from tskf_ros.core.timescale_kalman import FilterError
from tskf_ros.messages.estimator_interface import (ConfigError, diagnostics_message,
                                                   extractor, input_from_msg, INPUT_TOPIC,
                                                   MATRICES, measurement_class,
                                                   MEASUREMENT_TOPIC, NODE_NAME, NodeConfig,
                                                   OutcomeMessages, output_qos, OUTPUT_TOPICS,
                                                   parameters_to_config, raw_reader)
from tskf_ros.messages.qos import overridable, sensor_input_qos
from tskf_ros.nodes.input_watch import InputWatch
from tskf_ros.nodes.node_base import diagnostic_name, ReconfigurableNode
from tskf_ros.nodes.node_runner import run_node
from tskf_ros.owc.session import EstimatorSession, Outcome
from tskf_ros.owc.session.diagnostics import status_line

if TYPE_CHECKING:
    from tskf_ros.owc.lagged_estimates import LaggedEstimate, LaggedEstimates


class TimescaleEstimator(ReconfigurableNode):
    """Node wrapping EstimatorSession: received power in, estimates and diagnostics out."""

    SCHEMA = NODE_NAME
    SESSION = EstimatorSession
    CONFIG_ERRORS = (ConfigError, FilterError, KeyError, TypeError, ValueError)
    # x(t_j|t_j+L) of the smoothing_lag parameter, if one is given
    lagged: 'Optional[LaggedEstimates]'

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None,
                 cli_args: Optional[list] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides, cli_args=cli_args)
        qos_in = sensor_input_qos(self.config.queue_depth)
        msgtype = self.get_parameter('measurement_type').value
        self.extract = extractor(msgtype)
        # the measurements come serialized (raw): read from their fixed layout, no message
        # built (raw_reader); a message handed in directly is read by extract
        self.read = raw_reader(msgtype)
        self.sub = self.create_subscription(
            measurement_class(msgtype), MEASUREMENT_TOPIC, self._on_measurement, qos_in,
            event_callbacks=SubscriptionEventCallbacks(message_lost=self._on_lost), raw=True)
        self.input_sub = self.create_subscription(AccelStamped, INPUT_TOPIC, self._on_input,
                                                  qos_in)
        # the measurements (the inputs u are optional): named if nobody publishes them
        self.input_watch = InputWatch(self, [self.sub])
        # reliable, volatile, depth 10, each overridable by qos_overrides.<topic>.publisher.*
        # parameters (history, depth, reliability, durability)
        # (rclpy applies an override to the profile given: one profile per publisher)
        self.smoothing_lag = self.get_parameter('smoothing_lag').value
        self.lagged = None
        if self.smoothing_lag:      # (the smoother's modules only then)
            from tskf_ros.owc import lagged_estimates
            self.lagged = lagged_estimates.LaggedEstimates(self.smoothing_lag,
                                                           self.config.session)
        self.pubs = {key: self.create_publisher(
            Float64MultiArray, topic, output_qos(self.config),
            qos_overriding_options=overridable())
            for key, topic in OUTPUT_TOPICS.items() if key != 'smoothed' or self.lagged}
        self.outputs = OutcomeMessages(self.config)
        self.subscribed: set[str] = set()      # outputs with a subscriber (see _subscribed)
        self.start_diagnostics()
        self.watch_clock_jumps()
        self.start_services()
        m = self.config.session.model
        self.model_source = (
            f'parameters ({", ".join(self.matrices_given)} given)' if self.matrices_given else
            "the built-in default, Cai et al.'s model (3): no A, C, ... given; pass "
            '--params-file config/<model>_estimator.yaml to choose a model')
        start_line = (
            f'estimating {m.name} (n = {m.A.shape[0]}, states {", ".join(m.state_names)}) '
            f'with the {self.config.session.transition} transition; the model comes from '
            f'{self.model_source}')
        self.when_spinning(lambda: self.get_logger().info(start_line))

    # -- parameters -----------------------------------------------------------------------

    @property
    def matrices_given(self) -> tuple:
        """Return the model matrices given at start (the others hold model (3)'s values)."""
        return tuple(key for key in MATRICES if key in self.parameters_given)

    def make_config(self, values: dict) -> NodeConfig:
        """Build the node's config; raises with the reason if it makes no working filter."""
        return parameters_to_config(values)

    def reconfigure(self, config: NodeConfig) -> str:
        """Switch the session to a validated config; return what it did."""
        self.outputs = OutcomeMessages(config)
        message = self.session.reconfigure(config.session).message
        if self.lagged is not None:     # the window of the old model ends here
            self._publish_smoothed(self.lagged.reconfigure(config.session))
        return message

    # -- data -----------------------------------------------------------------------------

    def _on_measurement(self, msg: Any) -> None:
        now_ns = self.now_ns()
        # an unstamped type (std_msgs Float64, Float32) is stamped with its time of arrival
        stamp_ns, value, variance = (self.read if type(msg) is bytes else self.extract)(
            msg, now_ns)
        out = self.session.add(stamp_ns, value, variance, now_ns=now_ns)
        self._report(out)
        self._publish(out)

    def _on_lost(self, info: QoSMessageLostInfo) -> None:
        # the middleware's count of measurements lost in transport (diagnostics: filter
        # health); a queue overflow is not reported here
        self.session.stats.messages_lost = info.total_count

    def _on_input(self, msg: AccelStamped) -> None:
        out = self.session.add_input(*input_from_msg(msg, self.session))
        self._report(out)
        self._publish(out)

    def _report(self, out: Outcome) -> None:
        if out.status == 'accepted':        # the usual case: nothing to say
            return
        log = self.get_logger()
        if out.status == 'rejected':
            log.warning(f'sample rejected ({out.reason}): {out.message}')
        elif out.status == 'reset':
            log.warning(f'filter re-initialised ({out.reason}): {out.message}')
        elif out.status == 'inserted':
            log.info(out.message)
        elif out.status == 'gap':
            log.debug(out.message)

    def _publish(self, out: Outcome) -> None:
        # each message goes out serialized (the bytes rclpy would make of it); an output
        # nobody subscribes to (unless made transient_local) is neither filled nor published
        pubs = self.pubs
        for key, data in self.outputs.serialized(out, self._subscribed):
            pubs[key].publish(data)
        if self.lagged is not None:
            self._publish_smoothed(self.lagged.outcome(out))

    def _publish_smoothed(self, estimates: 'list[LaggedEstimate]') -> None:
        pub, outputs = self.pubs['smoothed'], self.outputs
        for e in estimates:
            pub.publish(outputs.smoothed_serialized(e.stamp_ns, e.mu, e.x, e.P))

    def _subscribed(self, key: str) -> bool:
        # a transient_local output (a durability override) is kept for late subscribers; a
        # subscriber once seen is taken as there until the next /diagnostics message (one
        # rclpy call per output and diagnostics period, not per input); none seen: asked
        # again at each estimate, so a new subscriber misses nothing
        if key in self.subscribed:
            return True
        pub = self.pubs[key]
        if (pub.get_subscription_count() > 0
                or pub.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL):
            self.subscribed.add(key)
            return True
        return False

    def publish_diagnostics(self) -> DiagnosticArray:
        """Publish (and return) the session's counters on /diagnostics; recount subscribers."""
        self.subscribed.clear()
        return super().publish_diagnostics()

    def restart(self, why: str, reason: str = 'clock_jump') -> None:
        """Re-initialise the filter, saying why (nothing to do before a sample)."""
        if self.session.pending() is None:
            return
        out = self.session.reset(reason, why)
        self.get_logger().warning(f'filter re-initialised: {out.message}')
        if self.lagged is not None:
            self._publish_smoothed(self.lagged.outcome(out))

    def status_line(self, rate: float) -> str:
        """Return the INFO status line: rate, gaps, last estimate, resets."""
        return status_line(self.session.stats, rate, self.session.kf.x)

    def diagnostics_message(self, stamp_ns: int) -> DiagnosticArray:
        """Return the session's counters as a /diagnostics message."""
        return diagnostics_message(self.session, self.config, stamp_ns,
                                   node_name=diagnostic_name(self))


DESCRIPTION = ('Time-scale Kalman filter on received power. Parameters '
               'come from a YAML file: --ros-args --params-file config/owc_estimator.yaml')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(TimescaleEstimator, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(ConfigError,), args=args)


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
