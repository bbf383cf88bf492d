"""Where a replay's outputs go: kept in memory, written to a bag, or kept as numpy arrays."""

from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Optional, Protocol, Sequence

import numpy as np
from numpy.typing import NDArray

from tskf_ros.bag.cdr import serialize
from tskf_ros.bag.reader import Damage, RawMessage
from tskf_ros.bag.replay.adapters import AnyOutcome, ESTIMATE_TOPICS, OfflineEstimator, Sample
from tskf_ros.bag.replay.rts_replay import SmoothingRecorder
from tskf_ros.bag.writer import BagWriter
from tskf_ros.core.units import NS
from tskf_ros.messages.estimator_interface import DIAGNOSTICS_TOPIC
from tskf_ros.owc.session.outcome import Run

__all__ = ['ArraySink', 'BagSink', 'Collector', 'ReplayResult', 'Sink', 'SMOOTHED_TOPIC']

# the RTS-smoothed estimates x(t|T) of replay_offline --smooth (the live node's fixed-lag
# smoothed topic, which has the same layout)
SMOOTHED_TOPIC = ESTIMATE_TOPICS['smoothed']
# (kind, revised) -> the name of its arrays (ArraySink): one set per kind of estimate
ARRAY_NAMES = {('predicted', False): 'estimate/predicted',
               ('corrected', False): 'estimate/corrected',
               ('mu', False): 'estimate/mu',
               ('predicted', True): 'estimate/revised/predicted',
               ('corrected', True): 'estimate/revised/corrected',
               ('mu', True): 'estimate/revised/mu'}


@dataclass
class ReplayResult:
    """What a replay did: counts, statuses, assumptions, damage, and collected outputs."""

    topic: str = ''
    msgtype: str = ''
    read: int = 0
    samples: int = 0
    written: Counter = field(default_factory=Counter)
    statuses: Counter = field(default_factory=Counter)
    assumptions: list[str] = field(default_factory=list)
    damage: Optional[Damage] = None
    seconds: float = 0.0
    outputs: list[tuple] = field(default_factory=list)  # (topic, log_ns, msg) when collecting
    input_topic: str = ''                               # the input u's topic ('' none)
    inputs: int = 0
    input_statuses: Counter = field(default_factory=Counter)


class Sink(Protocol):
    """What the replay loop hands every input message, outcome and /diagnostics message to."""

    copies: bool        # whether copy() does anything (the loop skips it if not)

    def copy(self, raw: RawMessage) -> None:
        """Take an input message as it was read."""

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Take what the session made of a measurement (is_input False) or an input u."""

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Take a /diagnostics message (rclpy) due at stamp_ns."""

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Take an rclpy message that the node publishes outside an outcome, as it starts."""


class Collector:
    """Outputs kept in memory as rclpy messages (result.outputs)."""

    copies = True

    def __init__(self, result: ReplayResult) -> None:
        self.result = result

    def copy(self, raw: RawMessage) -> None:
        """Keep the input message."""
        self.result.outputs.append((raw.topic, raw.log_time_ns, raw))

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Keep the messages the live node publishes for out."""
        for topic, msg in est.messages(out):
            self.result.written[topic] += 1
            self.result.outputs.append((topic, log_ns, msg))

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Keep the /diagnostics message."""
        self.message(DIAGNOSTICS_TOPIC, stamp_ns, msg)

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Keep the message."""
        self.result.written[topic] += 1
        self.result.outputs.append((topic, log_ns, msg))


class BagSink:
    """Outputs written to a bag, serialized to canonical CDR; the inputs copied as read."""

    copies = True

    def __init__(self, writer: BagWriter, result: ReplayResult,
                 smoother: Optional[SmoothingRecorder] = None) -> None:
        self.writer = writer
        self.written = result.written
        self.smoother = smoother
        self.last_log_ns = 0

    def copy(self, raw: RawMessage) -> None:
        """Write the input message's bytes as they were read (if its topic was added)."""
        if self.writer.has_topic(raw.topic):
            self.writer.write(raw.topic, raw.log_time_ns, raw.data)

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Write the messages the live node publishes for out, at the input's log time."""
        pairs = est.encoded(out)
        written = self.written
        for topic, _ in pairs:
            written[topic] += 1
        self.writer.write_many(log_ns, pairs)
        if self.smoother is not None:
            self.smoother.outcome(out)
            self.last_log_ns = max(self.last_log_ns, log_ns)

    def finish(self, est: OfflineEstimator) -> None:
        """Write the smoothed estimates (if smoothing), logged at the last input's time."""
        if self.smoother is None:
            return
        rows = self.smoother.smoothed()
        enc = est.encoder()
        # mu of each point's step, from the segment it belongs to
        stepped = [seg.sigma for seg in self.smoother.segments if seg.sigma]
        pairs = [(SMOOTHED_TOPIC, enc.estimate('smoothed', t, (stepped[s][t] - t) / NS, x, P))
                 for t, s, x, P in zip(rows.stamp_ns.tolist(), rows.segment.tolist(), rows.x,
                                       rows.P)]
        self.written[SMOOTHED_TOPIC] += len(pairs)
        if pairs:
            self.writer.write_many(self.last_log_ns, pairs)

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Write the /diagnostics message."""
        self.message(DIAGNOSTICS_TOPIC, stamp_ns, msg)

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Write the message, serialized to canonical CDR."""
        self.written[topic] += 1
        self.writer.write(topic, log_ns, serialize(msg))


class ArraySink:
    """
    The estimator's outputs as numpy arrays, one row per message of the output bag.

    Keys ('<topic>.<field>', the topic without its leading '/'):

    - sample.{log_ns, stamp_ns, value, variance, status, reason}: every measurement read
      (status accepted / inserted / gap / rejected / reset; reason why, or '');
    - input.{log_ns, stamp_ns, status}: every input u read (if the bag has one);
    - estimate/{predicted,corrected}.{log_ns, stamp_ns, x (rows x n), P (rows x n x n)},
      and estimate/revised/{predicted,corrected} for the estimates revised by a late
      sample (the messages of the topics estimate/predicted, estimate/corrected and
      estimate/revised);
    - estimate/mu.{log_ns, stamp_ns, sigma_ns, mu} (mu in s) and estimate/revised/mu: the
      steps t -> sigma(t) the filter took (the mu the estimate messages carry);
    - diagnostics.{log_ns, level, message}: per message, its worst task's level (0 OK ..
      3 STALE) and '<node>: <task>: <message>' (the first task at that level);
    - meta.{topic, input_topic, damage, assumptions}: strings;
    - with a smoother (replay_offline --smooth): estimate/smoothed.{stamp_ns, x, P,
      segment}, the RTS estimates x(t|T) at every stepped point, and the segment (0 first,
      a reset starts the next) each belongs to.
    """

    copies = False      # copy() does nothing: the loop need not call it

    def __init__(self, est: OfflineEstimator,
                 smoother: Optional[SmoothingRecorder] = None) -> None:
        self.smoother = smoother
        self.n = len(est.config.session.model.state_names)
        self.samples: list[tuple] = []
        self.inputs: list[tuple] = []
        self.estimates: dict[tuple, list] = {key: [] for key in ARRAY_NAMES}
        self.diag: list[tuple] = []

    def copy(self, raw: RawMessage) -> None:
        """Keep nothing of the inputs."""

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Keep a row of the sample and a row of each estimate and jump."""
        if is_input:
            self.inputs.append((log_ns, sample[0], out.status))
        else:
            self.samples.append((log_ns, *sample, out.status, out.reason))
        rows = self.estimates
        for e in out.estimates:
            rows[e.kind, e.revised].append((log_ns, e.stamp_ns, e.x, e.P))
        if self.smoother is not None:
            self.smoother.outcome(out)
        for j in out.jumps:
            rows['mu', j.revised].append((log_ns, j.stamp_ns, j.sigma_ns))

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Keep nothing: the estimator publishes no message outside an outcome."""

    def run_rows(self, run: Run, logs: Sequence[int], sampled: Sequence[Sample]) -> None:
        """Keep the rows `outcome` keeps for each sample of a run (all accepted, in order)."""
        self.samples += [(log_ns, *sample, 'accepted', '')
                         for log_ns, sample in zip(logs, sampled)]
        rows = self.estimates
        stamps, previous = run.stamps_ns.tolist(), run.previous_ns.tolist()
        rows['corrected', False] += zip(logs, previous, run.x_corrected, run.P_corrected)
        rows['predicted', False] += zip(logs, stamps, run.x_predicted, run.P_predicted)
        rows['mu', False] += zip(logs, previous, stamps)

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Keep a row of the /diagnostics message: the level and message of its worst task."""
        levels = [s.level[0] if isinstance(s.level, bytes) else int(s.level)
                  for s in msg.status]
        worst = max(range(len(levels)), key=levels.__getitem__)
        self.diag.append((stamp_ns, levels[worst],
                          f'{msg.status[worst].name}: {msg.status[worst].message}'))

    def arrays(self, result: ReplayResult) -> dict[str, NDArray]:
        """Return the dict of numpy arrays, keys as the class doc says."""
        out = {}
        i8, f8, n = np.int64, np.float64, self.n
        _columns(out, 'sample', self.samples, (('log_ns', i8), ('stamp_ns', i8),
                                               ('value', f8), ('variance', f8),
                                               ('status', str), ('reason', str)))
        if result.input_topic:
            _columns(out, 'input', self.inputs, (('log_ns', i8), ('stamp_ns', i8),
                                                 ('status', str)))
        for key, rows in self.estimates.items():
            name = ARRAY_NAMES[key]
            if key[0] == 'mu':
                _columns(out, name, rows, (('log_ns', i8), ('stamp_ns', i8),
                                           ('sigma_ns', i8)))
                out[f'{name}.mu'] = (out[f'{name}.sigma_ns'] - out[f'{name}.stamp_ns']) / NS
            else:
                cols = list(zip(*rows)) if rows else [(), (), (), ()]
                _columns(out, name, cols[:2], (('log_ns', i8), ('stamp_ns', i8)), zipped=True)
                out[f'{name}.x'] = _stacked(cols[2], (-1, n))
                out[f'{name}.P'] = _stacked(cols[3], (-1, n, n))
        _columns(out, 'diagnostics', self.diag, (('log_ns', i8), ('level', np.int8),
                                                 ('message', str)))
        if self.smoother is not None:
            smoothed = self.smoother.smoothed()
            name = SMOOTHED_TOPIC.lstrip('/')
            for column in smoothed._fields:
                out[f'{name}.{column}'] = getattr(smoothed, column)
        out['meta.topic'] = np.array(result.topic)
        out['meta.input_topic'] = np.array(result.input_topic)
        out['meta.damage'] = np.array(str(result.damage or ''))
        out['meta.assumptions'] = np.array(result.assumptions, dtype=str)
        return out


def _columns(out: dict[str, NDArray], name: str, rows: list, columns: tuple,
             zipped: bool = False) -> None:
    """Store the columns of `rows` (tuples) as out['name.column'] arrays of their dtypes."""
    if zipped:
        cols = rows
    else:
        cols = list(zip(*rows)) if rows else [()] * len(columns)
    for (column, dtype), values in zip(columns, cols):
        out[f'{name}.{column}'] = np.array(values, dtype=dtype)


def _stacked(arrays: tuple[NDArray, ...], shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Return the arrays (each of the same size) as one float64 array of `shape`."""
    if not arrays:
        return np.zeros(0, dtype=np.float64).reshape(shape)
    return np.concatenate(arrays, dtype=np.float64).reshape(shape)    # along their axis 0
