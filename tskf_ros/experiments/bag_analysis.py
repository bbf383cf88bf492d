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

"""Read a bag into a measurement and input stream, and evaluate the estimator on it."""

from collections import defaultdict
from dataclasses import dataclass, field
import os
from pathlib import Path
from typing import Optional

import numpy as np
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import DESERIALIZE_ERRORS, message_class
from tskf_ros.bag.progress import wrap
from tskf_ros.bag.reader import BagReader, Damage
from tskf_ros.bag.replay.model_check import check_model
from tskf_ros.bag.replay.rts_replay import SmoothingRecorder
from tskf_ros.bag.replay.topic_choice import choose_input_topic, choose_topic
from tskf_ros.core.nis_check import nis_summary
from tskf_ros.messages import conversions
from tskf_ros.messages.conversions import STATES_TYPE
from tskf_ros.messages.estimator_interface import extractor, INPUT_TYPE, NodeConfig
from tskf_ros.owc.innovation_trace import Input, Measurement, run_stream, StreamRun
from tskf_ros.owc.session import EstimatorConfig, REJECT_REASONS, RESET_REASONS

# metrics of evaluate_bag, in this order (the sweep's CSV columns after the key and settings)
METRICS = (['n_messages', 'accepted', 'inputs', 'steps', 'gaps', 'resets',
            'nis_n', 'nis_mean', 'nis_band_lo', 'nis_band_hi', 'nis_consistent',
            'nis_fraction_in_band', 'log_likelihood', 'truth_topic', 'truth_states',
            'truth_points', 'rms_corrected', 'rms_predicted', 'rms_smoothed']
           + [f'rejected_{r}' for r in REJECT_REASONS] + [f'resets_{r}' for r in RESET_REASONS]
           + ['damage'])


@dataclass
class Stream:
    """A bag read into events (Measurement, Input) plus the truth JointState topics."""

    path: str
    topic: str
    msgtype: str
    input_topic: str
    events: list = field(default_factory=list)
    truth: dict = field(default_factory=dict)    # topic -> {name: {stamp_ns: value}}
    assumptions: list = field(default_factory=list)
    damage: Optional[Damage] = None

    @property
    def measurements(self) -> int:
        """Return the number of measurement messages read."""
        return sum(isinstance(ev, Measurement) for ev in self.events)


def read_stream(bag: os.PathLike, config: EstimatorConfig, *, topic: Optional[str] = None,
                input_topic: Optional[str] = None, truth: bool = True,
                progress: bool = False) -> Stream:
    """
    Read a bag's measurements, inputs and (with truth) JointState topics in storage order.

    The measurement topic defaults to /received_power, the input topic to /input if the
    bag has it.
    Raises BagError / BagTypeError (one line) if the bag or its topics cannot be used, or
    WrongModelError if the bag is one of another model (bag/replay/model_check); damage
    met while reading stops it, and `Stream.damage` says where.  progress: a bar of the
    messages read (on a terminal).
    """
    reader = BagReader(bag)
    topic, msgtype, notes = choose_topic(reader, topic)
    in_topic, more = choose_input_topic(reader, input_topic)
    check_model(reader, in_topic, config.model)
    stream = Stream(str(bag), topic, msgtype, in_topic, assumptions=notes + more)
    cls, extract = message_class(msgtype), extractor(msgtype)
    m = config.model.B.shape[1] if config.model.B is not None else 1
    truth_topics = {t for t, i in reader.topics.items()
                    if truth and i.msgtype == STATES_TYPE}
    in_cls = message_class(INPUT_TYPE) if in_topic else None
    js_cls = message_class(STATES_TYPE) if truth_topics else None
    values: dict = defaultdict(lambda: defaultdict(dict))
    wanted = [topic] + ([in_topic] if in_topic else []) + sorted(truth_topics)
    counts = [reader.topics[t].count for t in wanted]
    total = sum(c for c in counts if c) if all(c is not None for c in counts) else None
    messages = wrap(reader.messages(wanted), total, 'reading', 'msg', progress)
    for count, raw in enumerate(messages):
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
                    values[raw.topic][name][stamp] = float(v)
        except DESERIALIZE_ERRORS as exc:
            # as the offline replay: what came before is used, the rest is damage
            stream.damage = Damage(str(reader.path), -1, f'message {count + 1} on {raw.topic} '
                                   f'does not deserialize as {raw.msgtype} ({exc})', count)
            break
    messages.close()
    stream.truth = {t: dict(v) for t, v in values.items()}
    stream.damage = stream.damage or reader.damage
    return stream


def truth_errors(run: StreamRun, stream: Stream, state_names: tuple,
                 smoothed: Optional[dict] = None) -> tuple[str, list, int, float, float, float]:
    """
    Return (truth topic, states matched, points, RMS corrected, predicted, smoothed).

    The truth topic is the JointState topic sharing the most joint names with the model's
    state names; the error is taken at every estimate stamp the truth has, over the
    matched states (root mean square over stamps and states).  smoothed: the RTS
    estimates as {(segment, stamp_ns): x} (NaN without).
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

    def rms(estimates: dict) -> tuple[int, float]:
        errs = []
        for (_, stamp), x in estimates.items():
            row = [x[i] - joints[n][stamp] for i, n in zip(index, names) if stamp in joints[n]]
            if len(row) == len(names):
                errs.append(row)
        if not errs:
            return 0, float('nan')
        e = np.asarray(errs)
        return len(errs), float(np.sqrt(np.mean(e * e)))

    points, rms_c = rms(run.corrected)
    _, rms_p = rms(run.predicted)
    _, rms_s = rms(smoothed) if smoothed is not None else (0, float('nan'))
    return best, names, points, rms_c, rms_p, rms_s


def stream_metrics(run: StreamRun, stream: Stream, config: EstimatorConfig,
                   smoothed: Optional[dict] = None) -> dict:
    """Return the metrics of METRICS for a session run over a stream (and its smoothing)."""
    st = run.stats
    p = config.model.C.shape[0]
    nis = nis_summary(run.innovations.nis, p)
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
                 input_topic: Optional[str] = None) -> dict:
    """
    Run the estimator over one bag, in memory; return {metric: value} (see METRICS).

    The session sees the measurements and inputs in storage order with the log time as
    the receiver clock, as the offline replay feeds them.  Raises BagError, BagTypeError
    or ValueError (one line) if the bag cannot be used; damage is reported in 'damage'.
    """
    session_config = config.session
    stream = read_stream(Path(bag), session_config, topic=topic, input_topic=input_topic)
    if stream.measurements == 0 and stream.damage is None:
        raise ValueError(f'{bag}: no messages on {stream.topic}')
    smoother = SmoothingRecorder(session_config)
    run = run_stream(session_config, stream.events, use_now=True, observe=smoother.outcome)
    rows = smoother.smoothed()
    smoothed = {(int(seg), int(t)): x for seg, t, x in zip(rows.segment, rows.stamp_ns, rows.x)}
    return stream_metrics(run, stream, session_config, smoothed)
