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
Read a bag into a measurement and input stream, and evaluate the estimator on it.

Memory: the events are kept as rows in a temporary file (`owc.stream_events.EventColumns`,
41 bytes a measurement on disk, a block in memory), the truth topics as columns of
(stamp, value) per joint (16 bytes a value), the session's final estimates as columns
(`owc.trace_columns`) and the smoothed ones as the smoother's rows: no object per
message is kept.
"""

from collections import defaultdict
from dataclasses import dataclass, field, replace
import os
from pathlib import Path
from typing import Callable, Optional, Protocol

import numpy as np
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import DESERIALIZE_ERRORS, message_class
from tskf_ros.bag.progress import wrap
from tskf_ros.bag.reader import BagReader, Damage
from tskf_ros.bag.replay.model_check import check_model
from tskf_ros.bag.replay.rts_replay import SmoothedRows, SmoothingRecorder
from tskf_ros.bag.replay.topic_choice import choose_input_topic, choose_topic
from tskf_ros.core.growing_column import Column
from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import SLOTS, STATES_TYPE
from tskf_ros.messages.estimator_interface import extractor, INPUT_TYPE, NodeConfig
from tskf_ros.owc.innovation_trace import (Event, EventColumns, Input, Measurement,
                                           StreamRun, StreamRunner)
from tskf_ros.owc.session import EstimatorConfig, REJECT_REASONS, RESET_REASONS

# metrics of evaluate_bag, in this order (the sweep's CSV columns after the key and settings)
METRICS = (['n_messages', 'accepted', 'inputs', 'steps', 'gaps', 'resets',
            'nis_n', 'nis_mean', 'nis_band_lo', 'nis_band_hi', 'nis_consistent',
            'nis_fraction_in_band', 'log_likelihood', 'truth_topic', 'truth_states',
            'truth_points', 'rms_corrected', 'rms_predicted', 'rms_smoothed']
           + [f'rejected_{r}' for r in REJECT_REASONS] + [f'resets_{r}' for r in RESET_REASONS]
           + ['damage'])


TICK = 4096     # read_stream's tick: messages between two calls


@dataclass(frozen=True)
class TopicChoice:
    """The topics read_stream reads from a bag, and how many messages that is."""

    topic: str
    msgtype: str
    input_topic: Optional[str]
    truth_topics: list
    notes: list                 # the assumptions the choice made (one line each)
    size: Optional[int]         # the messages on those topics (None: the index does not say)

    @property
    def wanted(self) -> list:
        """Return the topics in the order read_stream asks for them."""
        return [self.topic] + ([self.input_topic] if self.input_topic else []) \
            + self.truth_topics


def choose_topics(reader: BagReader, topic: Optional[str] = None,
                  input_topic: Optional[str] = None, truth: bool = True) -> TopicChoice:
    """
    Choose the measurement, input and (with truth) JointState topics of an open bag.

    The size is the count of the bag's index (the summary of an MCAP file, the rows of a
    SQLite3 bag).  Raises what the topic choice raises for a bag that cannot be used.
    """
    topic, msgtype, notes = choose_topic(reader, topic)
    in_topic, more = choose_input_topic(reader, input_topic)
    truth_topics = sorted(t for t, i in reader.topics.items()
                          if truth and i.msgtype == STATES_TYPE)
    choice = TopicChoice(topic, msgtype, in_topic, truth_topics, notes + more, None)
    counts = [reader.topics[t].count for t in choice.wanted]
    size = None if any(c is None for c in counts) else sum(counts)
    return replace(choice, size=size)


def stream_size(bag: os.PathLike, *, topic: Optional[str] = None,
                input_topic: Optional[str] = None, truth: bool = True,
                reader: Optional[BagReader] = None) -> Optional[int]:
    """
    Return how many messages read_stream reads from a bag (None if its index does not say).

    reader: the bag already open (its index read once for several questions).
    """
    reader = reader if reader is not None else BagReader(bag)
    return choose_topics(reader, topic, input_topic, truth).size


class EventSink(Protocol):
    """What read_stream appends the events to: EventColumns, StreamRunner."""

    @property
    def measurements(self) -> int:
        """Return the number of measurements appended."""

    def append(self, event: Event) -> None:
        """Take an event."""


class TruthSeries:
    """One joint's values of a truth topic: stamps (ns, sorted, unique) and values."""

    def __init__(self) -> None:
        self._stamp, self._value = Column(np.int64), Column(np.float64)
        self._sorted: Optional[tuple[np.ndarray, np.ndarray]] = None

    def add(self, stamp_ns: int, value: float) -> None:
        """Add a value (a later one at the same stamp replaces it)."""
        self._stamp.append(stamp_ns)
        self._value.append(value)
        self._sorted = None

    def _columns(self) -> tuple[np.ndarray, np.ndarray]:
        if self._sorted is None:
            stamps, values = self._stamp.view(), self._value.view()
            order = np.argsort(stamps, kind='stable')
            stamps, values = stamps[order], values[order]
            last = np.r_[stamps[1:] != stamps[:-1], True]   # the last value of each stamp
            self._sorted = (stamps[last], values[last])
        return self._sorted

    @property
    def stamps(self) -> np.ndarray:
        """Return the times (ns) with a value, sorted, each once."""
        return self._columns()[0]

    @property
    def values(self) -> np.ndarray:
        """Return the value at each stamp (the last one read there)."""
        return self._columns()[1]

    def at(self, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (which of `stamps` have a value, the values there)."""
        have, values = self._columns()
        if not have.size:
            return np.zeros(len(stamps), bool), np.zeros(0)
        i = np.searchsorted(have, stamps).clip(0, have.size - 1)
        hit = have[i] == stamps
        return hit, values[i[hit]]


@dataclass
class Stream:
    """A bag read into events (Measurement, Input) plus the truth JointState topics."""

    path: str
    topic: str
    msgtype: str
    input_topic: str
    events: 'EventSink' = field(default_factory=EventColumns)
    truth: dict = field(default_factory=dict)    # topic -> {name: TruthSeries}
    assumptions: list = field(default_factory=list)
    damage: Optional[Damage] = None

    @property
    def measurements(self) -> int:
        """Return the number of measurement messages read."""
        return self.events.measurements


def read_stream(bag: os.PathLike, config: EstimatorConfig, *, topic: Optional[str] = None,
                input_topic: Optional[str] = None, truth: bool = True,
                progress: bool = False,
                sink: Optional[Callable[[bool], EventSink]] = None,
                tick: Optional[Callable[[int], None]] = None) -> Stream:
    """
    Read a bag's measurements, inputs and (with truth) JointState topics in storage order.

    The measurement topic defaults to /received_power, the input topic to /input if the
    bag has it.
    Raises BagError / BagTypeError (one line) if the bag or its topics cannot be used, or
    WrongModelError if the bag is one of another model (bag/replay/model_check); damage
    met while reading stops it, and `Stream.damage` says where.  progress: a bar of the
    messages read (on a terminal).  sink: called with whether the bag has truth topics
    (with truth), it returns what the events are appended to as they are read (e.g. an
    innovation_trace.StreamRunner: the bag is run as it is read, no event kept); by
    default an EventColumns (`Stream.events`).  tick: called with the number of messages
    read since its last call, every TICK messages and at the end (a sweep's progress).
    """
    reader = BagReader(bag)
    choice = choose_topics(reader, topic, input_topic, truth)
    topic, msgtype, in_topic = choice.topic, choice.msgtype, choice.input_topic
    check_model(reader, in_topic, config.model)
    m = config.model.B.shape[1] if config.model.B is not None else 1
    events = (EventColumns(1, min(m, SLOTS)) if sink is None
              else sink(bool(choice.truth_topics)))
    stream = Stream(str(bag), topic, msgtype, in_topic, events, assumptions=choice.notes)
    cls, extract = message_class(msgtype), extractor(msgtype)
    in_cls = message_class(INPUT_TYPE) if in_topic else None
    js_cls = message_class(STATES_TYPE) if choice.truth_topics else None
    values: dict = defaultdict(lambda: defaultdict(TruthSeries))
    messages = wrap(reader.messages(choice.wanted), choice.size, 'reading', 'msg', progress)
    count = -1
    for count, raw in enumerate(messages):
        if tick is not None and count % TICK == TICK - 1:
            tick(TICK)
        try:
            if raw.topic == topic:
                stamp, value, variance = extract(deserialize_message(raw.data, cls),
                                                 raw.log_time_ns)
                stream.events.append(Measurement(stamp, value, variance, raw.log_time_ns))
            elif raw.topic == in_topic:
                stamp, u = conversions.msg_to_input(deserialize_message(raw.data, in_cls), m)
                stream.events.append(Input(stamp, u))
            else:
                msg = deserialize_message(raw.data, js_cls)
                stamp, pos = conversions.msg_to_angle(msg)
                for name, v in zip(msg.name, pos):
                    values[raw.topic][name].add(stamp, float(v))
        except DESERIALIZE_ERRORS as exc:
            # as the offline replay: what came before is used, the rest is damage
            stream.damage = Damage(str(reader.path), -1, f'message {count + 1} on {raw.topic} '
                                   f'does not deserialize as {raw.msgtype} ({exc})', count)
            break
    messages.close()
    if tick is not None and (count + 1) % TICK:
        tick((count + 1) % TICK)
    stream.truth = {t: dict(v) for t, v in values.items()}
    stream.damage = stream.damage or reader.damage
    return stream


def truth_errors(run: StreamRun, stream: Stream, state_names: tuple,
                 smoothed: Optional[SmoothedRows] = None
                 ) -> tuple[str, list, int, float, float, float]:
    """
    Return (truth topic, states matched, points, RMS corrected, predicted, smoothed).

    The truth topic is the JointState topic sharing the most joint names with the model's
    state names; the error is taken at every estimate stamp the truth has, over the
    matched states (root mean square over stamps and states).  run: a run_stream with
    estimates=True; smoothed: the RTS estimates (NaN without).
    """
    best, names = '', []
    for t, joints in sorted(stream.truth.items()):
        common = [n for n in state_names if n in joints]
        if len(common) > len(names):
            best, names = t, common
    if not names:
        return '', [], 0, float('nan'), float('nan'), float('nan')
    joints = stream.truth[best]
    index = [state_names.index(n) for n in names]

    def rms(stamps: np.ndarray, x: np.ndarray) -> tuple[int, float]:
        hit = np.ones(len(stamps), bool)
        for n in names:
            hit &= joints[n].at(stamps)[0]
        if not hit.any():
            return 0, float('nan')
        e = np.column_stack([x[hit, i] - joints[n].at(stamps[hit])[1]
                             for i, n in zip(index, names)])
        return int(hit.sum()), float(np.sqrt(np.mean(e * e)))

    if run.estimates is None:
        raise ValueError('truth_errors needs a run with its estimates (estimates=True)')
    points, rms_c = rms(*run.estimates.rows('corrected'))
    _, rms_p = rms(*run.estimates.rows('predicted'))
    _, rms_s = (rms(smoothed.stamp_ns, smoothed.x) if smoothed is not None
                else (0, float('nan')))
    return best, names, points, rms_c, rms_p, rms_s


def stream_metrics(run: StreamRun, stream: Stream, config: EstimatorConfig,
                   smoothed: Optional[SmoothedRows] = None) -> dict:
    """Return the metrics of METRICS for a session run over a stream (and its smoothing)."""
    st = run.stats
    nis = run.innovations.nis_summary()
    truth_topic, names, points, rms_c, rms_p, rms_s = truth_errors(
        run, stream, tuple(config.model.state_names), smoothed)
    out = {'n_messages': run.measurements, 'accepted': st.accepted, 'inputs': run.inputs,
           'steps': run.steps, 'gaps': st.gaps_total, 'resets': sum(st.resets.values()),
           'nis_n': nis['n'], 'nis_mean': nis['mean'], 'nis_band_lo': nis['band'][0],
           'nis_band_hi': nis['band'][1], 'nis_consistent': nis['consistent'],
           'nis_fraction_in_band': nis['fraction_in_band'],
           'log_likelihood': run.innovations.log_likelihood() if nis['n'] else None,
           'truth_topic': truth_topic, 'truth_states': ' '.join(names),
           'truth_points': points, 'rms_corrected': rms_c, 'rms_predicted': rms_p,
           'rms_smoothed': rms_s,
           'damage': str(stream.damage) if stream.damage is not None else ''}
    for r in REJECT_REASONS:
        out[f'rejected_{r}'] = st.rejected[r]
    for r in RESET_REASONS:
        out[f'resets_{r}'] = st.resets[r]
    return out


def evaluate_bag(bag: os.PathLike, config: NodeConfig, *, topic: Optional[str] = None,
                 input_topic: Optional[str] = None,
                 tick: Optional[Callable[[int], None]] = None) -> dict:
    """
    Run the estimator over one bag, in memory; return {metric: value} (see METRICS).

    The session sees the measurements and inputs in storage order with the log time as
    the receiver clock, as the offline replay feeds them.  Raises BagError, BagTypeError
    or ValueError (one line) if the bag cannot be used; damage is reported in 'damage'.
    tick: read_stream's (the messages read, as they are read).
    """
    session_config = config.session
    smoother: Optional[SmoothingRecorder] = None
    runner: Optional[StreamRunner] = None

    def make_runner(has_truth: bool) -> StreamRunner:
        # the session runs as the bag is read; the estimates (and the smoother) are kept
        # only for a bag with truth topics: the errors against it are all they are for
        nonlocal smoother, runner
        smoother = SmoothingRecorder(session_config) if has_truth else None
        runner = StreamRunner(session_config, use_now=True, trace=False, estimates=has_truth,
                              observe=smoother.outcome if smoother is not None else None)
        return runner
    stream = read_stream(Path(bag), session_config, topic=topic, input_topic=input_topic,
                         sink=make_runner, tick=tick)
    if stream.measurements == 0 and stream.damage is None:
        raise ValueError(f'{bag}: no messages on {stream.topic}')
    if runner is None:      # pragma: no cover - read_stream makes it before reading
        raise RuntimeError('read_stream did not make the runner')
    run = runner.result()
    return stream_metrics(run, stream, session_config,
                          smoother.smoothed() if smoother is not None else None)
