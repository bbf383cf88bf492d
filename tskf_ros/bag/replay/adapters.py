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

"""The live nodes' work on one bag message at a time, without DDS or a clock."""

from typing import Any, Callable, Optional, Union

import numpy as np
from numpy.typing import NDArray
from rclpy.qos import QoSProfile
from rosbags.serde import SerdeError

from tskf_ros.bag.cdr import EstimateEncoder, fixed_block_decoder, fixed_decoder, serialize
from tskf_ros.bag.message_types import typestore
from tskf_ros.core.units import NS
from tskf_ros.led.alignment_session import AlignmentSession, AlignOutcome
from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages import estimator_interface as estimator
from tskf_ros.messages.estimator_interface import (bag_outcome_messages, BAG_OUTPUT_TOPICS,
                                                   estimate_mu, extractor, input_from_msg,
                                                   INPUT_TYPE, INPUT_TYPES, NodeConfig,
                                                   output_key, output_qos, Sample,
                                                   sample_fields, step_mus)
from tskf_ros.owc.session import EstimatorSession, Outcome

__all__ = ['block_reader', 'ESTIMATE_TOPICS', 'OfflineAligner', 'OfflineEstimator',
           'sample_reader', 'Sample',
           'UNDECODABLE']

# what deserializing a message that is not of its type raises (rosbags' deserializer)
UNDECODABLE = (SerdeError,)
# output (predicted, corrected, revised, smoothed) -> bag topic of the estimates
ESTIMATE_TOPICS = BAG_OUTPUT_TOPICS
AnyOutcome = Union[Outcome, AlignOutcome]
AnyConfig = Union[NodeConfig, aligner.NodeConfig]


def sample_reader(msgtype: str,
                  extract: Callable[[Any, int], Sample]) -> Callable[[bytes, int], Sample]:
    """
    Return read(cdr bytes, log ns) -> (stamp ns, value, variance) for a type of INPUT_TYPES.

    What extract(rosbags' deserialize_cdr(data), log_ns) returns (or the SerdeError it
    raises), read from the bytes by cdr.fixed_decoder, or by rosbags where that leaves it.
    """
    deserialize = typestore().deserialize_cdr

    def slow(data: bytes, log_ns: int) -> Sample:
        return extract(deserialize(data, msgtype), log_ns)
    return estimator.sample_reader(msgtype, fixed_decoder(msgtype, sample_fields(msgtype)),
                                   slow)


Columns = tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]


def block_reader(msgtype: str) -> Callable[[NDArray[np.uint8], NDArray[np.int64]],
                                           Optional[Columns]]:
    """
    Return read(rows, log ns) -> (stamps ns, values, variances) of messages of one length.

    Row for row what sample_reader's read gives through cdr.fixed_decoder, as arrays; None
    where the fixed layout does not take every row (the caller reads them one by one).
    """
    kind = INPUT_TYPES[msgtype]
    decode = fixed_block_decoder(msgtype,
                                 [kind.value] + ([kind.variance] if kind.variance else []))

    def read(rows: NDArray[np.uint8], logs: NDArray[np.int64]) -> Optional[Columns]:
        got = decode(rows)
        if got is None:
            return None
        stamps = got[0] if kind.stamped else logs
        variances = (got[2].astype(np.float64) if kind.variance
                     else np.zeros(len(logs)))
        return stamps, got[1].astype(np.float64), variances
    return read


class OfflineEstimator:
    """The live timescale_estimator node's work on one message at a time."""

    interface = estimator   # the node's module in tskf_ros.messages
    session_class: type = EstimatorSession
    batched = True          # the replay loop may hand the session its samples in runs

    def __init__(self, config: AnyConfig, msgtype: str) -> None:
        self.config = config
        self.session = self.session_class(config.session)
        self.extract = extractor(msgtype)
        self.read_sample = sample_reader(msgtype, self.extract)
        self.read_block = block_reader(msgtype)
        self._deserialize = typestore().deserialize_cdr
        self.period_ns = int(round(config.diagnostics_period * NS))
        self.next_diag: Optional[int] = None
        self._encoder: Optional[EstimateEncoder] = None

    def output_topics(self) -> list[tuple[str, str, QoSProfile]]:
        """Return the (topic, type, rclpy QoS) of every output but /diagnostics."""
        qos = output_qos(self.config)
        # the smoothed estimates are written only by a replay that smooths (loop.replay)
        return [(name, estimator.output_type(key), qos)
                for key, name in BAG_OUTPUT_TOPICS.items() if key != 'smoothed']

    def start_messages(self) -> list[tuple[str, Any]]:
        """Return the (bag topic, rclpy message) pairs the live node publishes as it starts."""
        return []

    def diagnostics_due(self, log_ns: int) -> list[tuple[int, Any]]:
        """
        Return the /diagnostics message due at log_ns, if any: at most one.

        When several periods have elapsed since the last one, the message is stamped at the
        latest due time (the others would repeat the same state).
        """
        if self.period_ns <= 0:
            return []
        if self.next_diag is None:
            self.next_diag = log_ns + self.period_ns
        if log_ns < self.next_diag:
            return []
        due = self.next_diag + (log_ns - self.next_diag) // self.period_ns * self.period_ns
        self.next_diag = due + self.period_ns
        return [(due, self.interface.diagnostics_message(self.session, self.config, due))]

    def process(self, data: bytes, log_ns: int) -> tuple[Sample, AnyOutcome]:
        """Decode one measurement and run it; return ((stamp, value, variance), outcome)."""
        sample = self.read_sample(data, log_ns)
        return sample, self.session.add(*sample, now_ns=log_ns)

    def process_input(self, data: bytes, log_ns: int) -> tuple[tuple, Outcome]:
        """Deserialize one input u (rosbags) and run it; return ((stamp, u), outcome)."""
        sample = input_from_msg(self._deserialize(data, INPUT_TYPE), self.session)
        return sample, self.session.add_input(*sample)

    def messages(self, out: AnyOutcome) -> list[tuple[str, Any]]:
        """Return the (bag topic, rclpy message) pairs the live node publishes for out."""
        return bag_outcome_messages(out, self.config)

    def encoder(self) -> EstimateEncoder:
        """Return the replay's encoder of the estimate messages (made once)."""
        if self._encoder is None:
            self._encoder = EstimateEncoder(self.config.session.model.state_names)
        return self._encoder

    def encoded(self, out: AnyOutcome) -> list[tuple[str, bytes]]:
        """Return what messages(out) returns, serialized (canonical CDR, EstimateEncoder)."""
        enc = self._encoder or self.encoder()
        mus = step_mus(out)
        return [(ESTIMATE_TOPICS[output_key(e.kind, e.revised)],
                 enc.estimate(e.kind, e.stamp_ns, estimate_mu(e.kind, e.stamp_ns, mus), e.x,
                              e.P))
                for e in out.estimates]


class OfflineAligner(OfflineEstimator):
    """The live alignment node's work on one message at a time."""

    interface = aligner
    session_class = AlignmentSession
    batched = False

    def output_topics(self) -> list[tuple[str, str, QoSProfile]]:
        """Return the (topic, type, rclpy QoS) of every output but /diagnostics."""
        return [(name, aligner.OUTPUT_TYPES[key], aligner.output_qos(self.config, key))
                for key, name in aligner.BAG_OUTPUT_TOPICS.items()] + [
                    (aligner.BAG_PAT_STATE_TOPIC, aligner.PAT_STATE_TYPE,
                     aligner.pat_state_qos())]

    def start_messages(self) -> list[tuple[str, Any]]:
        """Return the pat_state message of the state the session starts in (taken from it)."""
        return aligner.bag_pat_state_messages(self.session.take_transitions())

    def process(self, data: bytes, log_ns: int) -> tuple[Sample, AnyOutcome]:
        """Decode one intensity sample and run it; return (sample, outcome)."""
        sample = self.read_sample(data, log_ns)
        return sample, self.session.add(sample[0], sample[1], now_ns=log_ns)

    def messages(self, out: AnyOutcome) -> list[tuple[str, Any]]:
        """
        Return the (bag topic, rclpy message) pairs the live node publishes for out.

        Its outputs, then a pat_state message per state transition the sample made (taken
        from the session, as the node does after publishing: call once per outcome).
        """
        return (aligner.bag_outcome_messages(out, self.config)
                + aligner.bag_pat_state_messages(self.session.take_transitions()))

    def encoded(self, out: AnyOutcome) -> list[tuple[str, bytes]]:
        """Return what messages(out) returns, serialized (canonical CDR, rosbags)."""
        return [(topic, serialize(msg)) for topic, msg in self.messages(out)]
