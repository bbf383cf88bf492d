"""
replay_offline: run the time-scale estimator over a bag as fast as possible, without DDS.

    replay_offline bags/owc_cai_td_1hz /tmp/owc_estimated --params-file config/owc_estimator.yaml
    replay_offline --filter alignment bags/led_alignment /tmp/led_aligned \
        --params-file config/alignment.yaml

Reads the measurement topic (default /received_power) and the input topic (--input-topic,
default /input if the bag has it: geometry_msgs/AccelStamped, the model's u), feeds every
message in log-time order to the same EstimatorSession the live timescale_estimator node
runs (add and add_input), and writes a new bag with all the
input topics and every topic the live node would publish (estimate/predicted,
estimate/corrected, estimate/mu, their revised/ versions and /diagnostics), with the same
message types and header stamps.  An output message's log time is the log time of the
input message that produced it (the live node publishes on receipt); /diagnostics is
emitted every diagnostics_period seconds of log time, as the node's timer would, but at
most once per input message: when several periods elapsed between two messages (a gap in
the log times, a clock that jumps from boot time to the present), one /diagnostics
message is written at the latest due time, not one per period (the output stays bounded by
the input, however long the span of its clock).

Outputs are canonical CDR (tskf_ros.bag.cdr); the input topics are copied as they are.

Analysis mode: --npz FILE writes no bag but the outputs as numpy arrays (ArraySink); from
Python, replay_arrays(bag, config) returns them.

--filter alignment runs the alignment node's AlignmentSession instead (tskf_ros.messages.
alignment_interface) on the intensity topic (default /intensity, else the only stamped scalar
topic, e.g. /photodiode of bags/led_alignment) and writes what that node publishes:
base_position_controller/commands, estimate/predicted and estimate/corrected (EKF) and
/diagnostics.  This is open loop: the commands do not move the recorded receiver, so the
output shows the filter on the recorded intensities (the output's metadata says so).

Bags from elsewhere: --topic picks the measurement topic; the stamped scalars of
common_interfaces in INPUT_TYPES are taken (Range has no variance: 0; std_msgs Float64 /
Float32 have no stamp: the log time is used, with a warning); sqlite3 bags work too.

Exit status: 0 done; 1 the bag (or parameters) could not be used (one-line error);
3 the input was damaged: the messages before the damage were processed and written,
the damage is reported, and the output's metadata says so (custom_data).
"""

import argparse
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, field
import gc
import os
from pathlib import Path
import sys
import tempfile
import time
from typing import Callable, Iterator, Optional

import numpy as np
from rclpy.serialization import deserialize_message

from tskf_ros.bag.cdr import EstimateEncoder, fixed_decoder, serialize
from tskf_ros.bag.message_types import BagTypeError, message_class, qos_from_rclpy, typestore
from tskf_ros.bag.reader import (BagError, BagReader, Damage, error_exit, EXIT_DAMAGED,
                                 exit_status)
from tskf_ros.bag.writer import BagExistsError, BagWriter
from tskf_ros.core.units import NS
from tskf_ros.led.alignment_session import AlignmentSession
from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages import estimator_interface as estimator
from tskf_ros.messages.estimator_interface import (BAG_INPUT_TOPIC, bag_outcome_messages,
                                                   BAG_OUTPUT_TOPICS, BAG_POWER_TOPIC,
                                                   DIAGNOSTICS_TOPIC, DIAGNOSTICS_TYPE,
                                                   extractor, input_from_msg, INPUT_TYPE,
                                                   INPUT_TYPES, load_config,
                                                   NodeConfig, output_qos, ParamsError)
from tskf_ros.owc.session import EstimatorSession

PROG = 'replay_offline'
# exceptions rclpy's deserializer raises on bytes that are not the type
DESERIALIZE_ERRORS = (RuntimeError, ValueError, TypeError)
FILTERS = ('estimator', 'alignment')
# filter -> (default input topic, suffix of the default output)
FILTER_INPUT = {'estimator': (BAG_POWER_TOPIC, '_estimated'),
                'alignment': (aligner.BAG_INPUT_TOPIC, '_aligned')}


class InputError(BagError):
    """The bag has no usable measurement topic, or it has an unsupported type."""


@dataclass
class ReplayResult:
    """What a replay did: counts, statuses, assumptions, damage, and collected outputs."""

    topic: str = ''
    msgtype: str = ''
    read: int = 0
    samples: int = 0
    written: Counter = field(default_factory=Counter)
    statuses: Counter = field(default_factory=Counter)
    assumptions: list = field(default_factory=list)
    damage: Optional[Damage] = None
    seconds: float = 0.0
    outputs: list = field(default_factory=list)     # (topic, log_ns, msg) when collecting
    input_topic: str = ''                           # the input u's topic ('' none)
    inputs: int = 0
    input_statuses: Counter = field(default_factory=Counter)


def choose_topic(reader: BagReader, topic: Optional[str],
                 default: str = BAG_POWER_TOPIC) -> tuple[str, str, list]:
    """
    Pick the measurement topic and its type; return (topic, type, assumptions).

    Without --topic: `default` (/received_power) if present, else the only topic of a
    known type.
    """
    assumptions = []
    if topic is None:
        if default in reader.topics:
            topic = default
        else:
            known = [t for t, i in reader.topics.items() if i.msgtype in INPUT_TYPES]
            if len(known) != 1:
                raise InputError(
                    f'{reader.path}: no {default} topic and '
                    f'{"no" if not known else len(known)} stamped scalar topics '
                    f'({", ".join(known) or "none"}); choose one with --topic')
            topic = known[0]
            assumptions.append(f'no {default}: using {topic}, the only stamped scalar '
                               'topic of the bag')
    info = reader.topics.get(topic)
    if info is None:
        raise InputError(f'{reader.path}: no topic {topic} (topics: '
                         f'{", ".join(sorted(reader.topics)) or "none"})')
    if info.msgtype not in INPUT_TYPES:
        raise InputError(f'{reader.path}: topic {topic} has type {info.msgtype or "unknown"}, '
                         f'not one this replay takes ({", ".join(INPUT_TYPES)})')
    kind = INPUT_TYPES[info.msgtype]
    field_text = f'{info.msgtype}.{kind.value}'
    assumptions.append(f'{topic} ({field_text}) is the measurement y of the model')
    if kind.variance is None and kind.stamped:
        assumptions.append(f'{info.msgtype} has no variance field: variance 0 (unknown)')
    if not kind.stamped:
        assumptions.append(f"WARNING: {info.msgtype} has no header stamp: the bag's log "
                           '(receive) time is used as the sample time, so mu includes '
                           'transport and recording jitter')
    if reader.storage == 'sqlite3':
        assumptions.append('sqlite3 storage (older rosbag2): read with rosbags')
    return topic, info.msgtype, assumptions


def choose_input_topic(reader: BagReader, topic: Optional[str]) -> tuple[str, list]:
    """
    Pick the input u's topic; return (topic or '', assumptions).

    Without --input-topic: /input if the bag has it, else none.
    """
    if topic is None:
        if BAG_INPUT_TOPIC not in reader.topics:
            return '', []
        topic = BAG_INPUT_TOPIC
    info = reader.topics.get(topic)
    if info is None:
        raise InputError(f'{reader.path}: no input topic {topic} (topics: '
                         f'{", ".join(sorted(reader.topics)) or "none"})')
    if info.msgtype != INPUT_TYPE:
        raise InputError(f'{reader.path}: input topic {topic} has type '
                         f'{info.msgtype or "unknown"}, not {INPUT_TYPE}')
    return topic, [f'{topic} ({INPUT_TYPE}, slot i = u[i]) is the input u of the model, held '
                   'from each stamp to the next (zero-order hold)']


def sample_reader(msgtype: str, cls: type, extract: Callable) -> Callable[[bytes, int], tuple]:
    """
    Return read(cdr bytes, log ns) -> (stamp ns, value, variance) for a type of INPUT_TYPES.

    What extract(deserialize_message(data, cls), log_ns) returns, read from the bytes by
    cdr.fixed_decoder; bytes it does not take (big-endian, too short) go through rclpy,
    whose values or error stand (test/test_bag_replay.py compares the two on Hypothesis'
    messages and mutations of them).
    """
    kind = INPUT_TYPES[msgtype]
    decode = fixed_decoder(msgtype, [kind.value] + ([kind.variance] if kind.variance else []))

    def slow(data: bytes, log_ns: int) -> tuple:
        return extract(deserialize_message(data, cls), log_ns)
    if not kind.stamped:
        def read_plain(data: bytes, log_ns: int) -> tuple:
            got = decode(data)
            return slow(data, log_ns) if got is None else (int(log_ns), got[1], 0.0)
        return read_plain
    if kind.variance is None:
        def read_no_variance(data: bytes, log_ns: int) -> tuple:
            got = decode(data)
            return slow(data, log_ns) if got is None else (got[0], got[1], 0.0)
        return read_no_variance

    def read(data: bytes, log_ns: int) -> tuple:
        return decode(data) or slow(data, log_ns)
    return read


class OfflineEstimator:
    """The live node's work on one message at a time, without DDS or a clock."""

    interface = estimator   # the node's module in tskf_ros.messages
    session_class: type = EstimatorSession

    def __init__(self, config: NodeConfig, msgtype: str) -> None:
        self.config = config
        self.session = self.session_class(config.session)
        self.cls = message_class(msgtype)
        self.input_cls = message_class(INPUT_TYPE)
        self.extract = extractor(msgtype)
        self.read_sample = sample_reader(msgtype, self.cls, self.extract)
        self.period_ns = int(round(config.diagnostics_period * NS))
        self.next_diag: Optional[int] = None
        self._encoder: Optional[EstimateEncoder] = None

    def output_topics(self) -> list:
        """Return the (topic, type, rclpy QoS) of every output but /diagnostics."""
        qos = output_qos(self.config)
        return [(name, estimator.output_type(key), qos)
                for key, name in BAG_OUTPUT_TOPICS.items()]

    def diagnostics_due(self, log_ns: int) -> list:
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

    def process(self, data: bytes, log_ns: int) -> tuple[tuple, object]:
        """Decode one measurement and run it; return ((stamp, value, variance), outcome)."""
        sample = self.read_sample(data, log_ns)
        return sample, self.session.add(*sample, now_ns=log_ns)

    def process_input(self, data: bytes, log_ns: int) -> tuple[tuple, object]:
        """Deserialize one input u and run it; return ((stamp, u), outcome)."""
        sample = input_from_msg(deserialize_message(data, self.input_cls), self.session)
        return sample, self.session.add_input(*sample)

    def messages(self, out: object) -> list:
        """Return the (bag topic, rclpy message) pairs the live node publishes for out."""
        return bag_outcome_messages(out, self.config)

    def encoded(self, out: object) -> list:
        """Return what messages(out) returns, serialized (canonical CDR, fixed layout)."""
        enc = self._encoder
        if enc is None:
            names = self.config.session.model.state_names
            enc = self._encoder = EstimateEncoder(self.config.frame_id, names, len(names))
        pairs = []
        for e in out.estimates:
            key = e.kind, e.revised
            twist, states = enc.pair(e.stamp_ns, e.x, e.P)
            pairs += ((_ESTIMATE_TOPICS[key], twist), (_STATES_TOPICS[key], states))
        pairs += [(_ESTIMATE_TOPICS['mu', j.revised], enc.jump(j.stamp_ns, j.sigma_ns))
                  for j in out.jumps]
        return pairs


_ESTIMATE_TOPICS = BAG_OUTPUT_TOPICS
_STATES_TOPICS = {(kind, revised): BAG_OUTPUT_TOPICS[kind + '_states', revised]
                  for kind, revised in BAG_OUTPUT_TOPICS if not kind.endswith('_states')
                  and kind != 'mu'}


class OfflineAligner(OfflineEstimator):
    """The live alignment node's work on one message at a time, without DDS or a clock."""

    interface = aligner
    session_class = AlignmentSession

    def output_topics(self) -> list:
        """Return the (topic, type, rclpy QoS) of every output but /diagnostics."""
        return [(name, aligner.OUTPUT_TYPES[key], aligner.output_qos(self.config, key))
                for key, name in aligner.BAG_OUTPUT_TOPICS.items()]

    def process(self, data: bytes, log_ns: int) -> tuple[tuple, object]:
        """Decode one intensity sample and run it; return (sample, outcome)."""
        sample = self.read_sample(data, log_ns)
        return sample, self.session.add(sample[0], sample[1], now_ns=log_ns)

    def messages(self, out: object) -> list:
        """Return the (bag topic, rclpy message) pairs the live node publishes for out."""
        return aligner.bag_outcome_messages(out, self.config)

    def encoded(self, out: object) -> list:
        """Return what messages(out) returns, serialized (canonical CDR, rosbags)."""
        return [(topic, serialize(msg)) for topic, msg in self.messages(out)]


def _prepare(bag: os.PathLike, config: object, topic: Optional[str], filter: str,  # noqa: A002
             input_topic: Optional[str], log: Callable[[str], None]
             ) -> tuple[BagReader, OfflineEstimator, ReplayResult]:
    """Open the bag, load the config, choose the topics; raise before anything is written."""
    if filter not in FILTERS:
        raise ValueError(f'filter must be one of {FILTERS}, got {filter!r}')
    reader = BagReader(bag)
    aligning = filter == 'alignment'
    if not isinstance(config, (estimator.NodeConfig, aligner.NodeConfig)):
        config = (aligner.load_config if aligning else load_config)(config)
    result = ReplayResult()
    result.topic, result.msgtype, result.assumptions = choose_topic(
        reader, topic, FILTER_INPUT[filter][0])
    if aligning:
        result.assumptions.append(aligner.OPEN_LOOP_NOTE)
    else:
        result.input_topic, notes = choose_input_topic(reader, input_topic)
        result.assumptions += notes
    for line in result.assumptions:
        log(line)
    est = (OfflineAligner if aligning else OfflineEstimator)(config, result.msgtype)
    return reader, est, result


def replay(bag: os.PathLike, output: Optional[os.PathLike] = None, *,
           params_file: Optional[os.PathLike] = None, topic: Optional[str] = None,
           overwrite: bool = False, compress: bool = False, diagnostics: bool = True,
           log: Callable[[str], None] = lambda s: None,
           filter: str = 'estimator',  # noqa: A002 (the CLI's --filter)
           input_topic: Optional[str] = None) -> ReplayResult:
    """
    Run the estimator over `bag`; write `output` (a new bag) or, if None, collect in memory.

    filter='alignment' runs the alignment node's session instead (open loop, see above).
    input_topic: the estimator's input u (default /input if present; see choose_input_topic).
    In memory, `result.outputs` holds (topic, log time, rclpy message or the input's
    RawMessage) in order.

    Raises BagError / ParamsError / BagTypeError before anything is written if the bag or
    the parameters cannot be used.  Damage met while reading stops the replay; what came
    before is processed and written, and `result.damage` says where it stopped.
    """
    t0 = time.perf_counter()
    if output is not None:
        _check_output(Path(bag), Path(output), overwrite)
    reader, est, result = _prepare(bag, params_file, topic, filter, input_topic, log)
    if output is None:
        result.damage = _run(reader, est, _Collect(result), result, diagnostics)
        result.seconds = time.perf_counter() - t0
        return result
    writer = BagWriter(output, overwrite=overwrite, compress=compress)
    writer.open()
    try:
        _add_topics(writer, reader, est, diagnostics, log)
        if filter == 'alignment':
            writer.set_custom_data('tskf_ros.open_loop', aligner.OPEN_LOOP_NOTE)
        with _gc_paused(filter == 'estimator'):
            result.damage = _run(reader, est, _BagSink(writer, result), result, diagnostics)
        if result.damage is not None:
            writer.set_custom_data('tskf_ros.input_damage', str(result.damage))
        writer.close()
    except BaseException:
        writer.abort()
        raise
    result.seconds = time.perf_counter() - t0
    return result


def replay_arrays(bag: os.PathLike, config: object = None, *, topic: Optional[str] = None,
                  input_topic: Optional[str] = None, diagnostics: bool = True,
                  log: Callable[[str], None] = lambda s: None) -> dict:
    """
    Run the estimator over `bag` and return its outputs as numpy arrays; write nothing.

    config: a NodeConfig (estimator_interface.load_config / parameters_to_config), a
    parameter file, or None for the node's defaults.  The keys (see ArraySink) hold what
    the output bag's topics hold, one row per message; 'meta.damage' is '' or the damage
    that stopped the reading (the rows are what came before it).  Raises as replay().
    """
    reader, est, result = _prepare(bag, config, topic, 'estimator', input_topic, log)
    sink = ArraySink(est)
    with _gc_paused():
        result.damage = _run(reader, est, sink, result, diagnostics)
        arrays = sink.arrays(result)
        del sink            # its rows go now, before the collector would scan them
    return arrays


@contextmanager
def _gc_paused(pause: bool = True) -> Iterator[None]:
    """
    Pause Python's cyclic garbage collector (if it runs) for the estimator's replay loop.

    The loop keeps the tuples it makes (arrays rows) or drops them at once (bag mode), and
    makes no reference cycles (a few hundred objects in cycles after a whole run of
    bags/owc_ge_1khz): the collector would only rescan what is kept, a fifth of the
    arrays mode's time (bench/bench_offline.py).  Reference counting still frees
    everything else; the collector is restored on the way out, whatever happens.
    """
    was = pause and gc.isenabled()
    if was:
        gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def _add_topics(writer: BagWriter, reader: BagReader, est: OfflineEstimator,
                diagnostics: bool, log: Callable[[str], None]) -> None:
    """Add the input bag's topics (those with a definition) and the node's outputs."""
    store = typestore()
    for name, info in reader.topics.items():
        if info.msgtype in store.fielddefs or info.msgdef:
            writer.add_topic(name, info.msgtype, qos=info.qos, msgdef=info.msgdef)
        else:
            log(f'{name}: type {info.msgtype} has no definition here; not copied')
    for name, msgtype, qos in est.output_topics():
        if not writer.has_topic(name):
            writer.add_topic(name, msgtype, qos=[qos_from_rclpy(qos)])
    if diagnostics and not writer.has_topic(DIAGNOSTICS_TOPIC):
        writer.add_topic(DIAGNOSTICS_TOPIC, DIAGNOSTICS_TYPE, qos=[qos_from_rclpy(
            est.output_topics()[0][2])])


def _check_output(bag: Path, output: Path, overwrite: bool) -> None:
    """Raise a BagError if `output` cannot be written (before anything is read or made)."""
    out, src = output.resolve(), bag.resolve()
    if out == src or src.is_relative_to(out) or out.is_relative_to(src):
        raise BagExistsError(f'{output}: is (or holds, or is inside) the input bag {bag}; '
                             'give another output')
    BagWriter(output, overwrite=overwrite).check_target()


class _Collect:
    """Outputs kept in memory as rclpy messages (result.outputs)."""

    def __init__(self, result: ReplayResult) -> None:
        self.result = result

    def copy(self, raw: object) -> None:
        self.result.outputs.append((raw.topic, raw.log_time_ns, raw))

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: object,
                is_input: bool) -> None:
        for topic, msg in est.messages(out):
            self.result.written[topic] += 1
            self.result.outputs.append((topic, log_ns, msg))

    def diagnostics(self, stamp_ns: int, msg: object) -> None:
        self.result.written[DIAGNOSTICS_TOPIC] += 1
        self.result.outputs.append((DIAGNOSTICS_TOPIC, stamp_ns, msg))


class _BagSink:
    """Outputs written to a bag, serialized to canonical CDR."""

    def __init__(self, writer: BagWriter, result: ReplayResult) -> None:
        self.writer = writer
        self.written = result.written

    def copy(self, raw: object) -> None:
        if self.writer.has_topic(raw.topic):
            self.writer.write(raw.topic, raw.log_time_ns, raw.data)

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: object,
                is_input: bool) -> None:
        write = self.writer.write
        for topic, data in est.encoded(out):
            self.written[topic] += 1
            write(topic, log_ns, data)

    def diagnostics(self, stamp_ns: int, msg: object) -> None:
        self.written[DIAGNOSTICS_TOPIC] += 1
        self.writer.write(DIAGNOSTICS_TOPIC, stamp_ns, serialize(msg))


class ArraySink:
    """
    The estimator's outputs as numpy arrays, one row per message of the output bag.

    Keys ('<topic>.<field>', the topic without its leading '/'):

    - sample.{log_ns, stamp_ns, value, variance, status, reason}: every measurement read
      (status accepted / inserted / gap / rejected / reset; reason why, or '');
    - input.{log_ns, stamp_ns, status}: every input u read (if the bag has one);
    - estimate/{predicted,corrected}.{log_ns, stamp_ns, x (rows x n), P (rows x n x n)},
      and estimate/revised/... for the estimates revised by a late sample: the
      TwistWithCovarianceStamped topics (their *_states mirrors are x and sqrt(diag P));
    - estimate/mu.{log_ns, stamp_ns, sigma_ns, mu} (mu in s) and estimate/revised/mu;
    - diagnostics.{log_ns, level, message} (level 0 OK .. 3 STALE);
    - meta.{topic, input_topic, damage, assumptions}: strings.
    """

    copies = False      # copy() does nothing: _run need not call it

    def __init__(self, est: OfflineEstimator) -> None:
        self.n = len(est.config.session.model.state_names)
        self.samples: list = []
        self.inputs: list = []
        self.estimates: dict = {key: [] for key in _ESTIMATE_TOPICS}
        self.diag: list = []

    def copy(self, raw: object) -> None:
        pass

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: object,
                is_input: bool) -> None:
        if is_input:
            self.inputs.append((log_ns, sample[0], out.status))
        else:
            self.samples.append((log_ns, *sample, out.status, out.reason))
        rows = self.estimates
        for e in out.estimates:
            rows[e.kind, e.revised].append((log_ns, e.stamp_ns, e.x, e.P))
        for j in out.jumps:
            rows['mu', j.revised].append((log_ns, j.stamp_ns, j.sigma_ns))

    def diagnostics(self, stamp_ns: int, msg: object) -> None:
        status = msg.status[0]
        level = status.level
        self.diag.append((stamp_ns, level[0] if isinstance(level, bytes) else int(level),
                          status.message))

    def arrays(self, result: ReplayResult) -> dict:
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
            name = _ESTIMATE_TOPICS[key].lstrip('/')
            if key[0] == 'mu':
                _columns(out, name, rows, (('log_ns', i8), ('stamp_ns', i8),
                                           ('sigma_ns', i8)))
                out[f'{name}.mu'] = (out[f'{name}.sigma_ns'] - out[f'{name}.stamp_ns']) / NS
            elif not key[0].endswith('_states'):
                cols = list(zip(*rows)) if rows else [(), (), (), ()]
                _columns(out, name, cols[:2], (('log_ns', i8), ('stamp_ns', i8)), zipped=True)
                out[f'{name}.x'] = _stacked(cols[2], (-1, n))
                out[f'{name}.P'] = _stacked(cols[3], (-1, n, n))
        _columns(out, 'diagnostics', self.diag, (('log_ns', i8), ('level', np.int8),
                                                 ('message', str)))
        out['meta.topic'] = np.array(result.topic)
        out['meta.input_topic'] = np.array(result.input_topic)
        out['meta.damage'] = np.array(str(result.damage or ''))
        out['meta.assumptions'] = np.array(result.assumptions, dtype=str)
        return out


def _columns(out: dict, name: str, rows: list, columns: tuple, zipped: bool = False) -> None:
    """Store the columns of `rows` (tuples) as out['name.column'] arrays of their dtypes."""
    if zipped:
        cols = rows
    else:
        cols = list(zip(*rows)) if rows else [()] * len(columns)
    for (column, dtype), values in zip(columns, cols):
        out[f'{name}.{column}'] = np.array(values, dtype=dtype)


def _stacked(arrays: tuple, shape: tuple) -> np.ndarray:
    """Return the arrays (each of the same size) as one float64 array of `shape`."""
    if not arrays:
        return np.zeros(0, dtype=np.float64).reshape(shape)
    return np.concatenate(arrays, dtype=np.float64).reshape(shape)    # along their axis 0


def _run(reader: BagReader, est: OfflineEstimator, sink: object, result: ReplayResult,
         diagnostics: bool) -> Optional[Damage]:
    """Read, estimate, hand the outputs to the sink; return the damage that stopped it."""
    topic, input_topic = result.topic, result.input_topic
    process, process_input = est.process, est.process_input
    copy = sink.copy if getattr(sink, 'copies', True) else None
    outcome = sink.outcome
    statuses = result.statuses
    # the log time from which est.diagnostics_due may have something (None: never)
    due_at = -1 if diagnostics else None
    read = samples = 0          # result.read and result.samples, kept in locals
    try:
        for raw in reader.messages():
            read += 1
            log_ns = raw.log_time_ns
            if due_at is not None and log_ns >= due_at:
                for t, msg in est.diagnostics_due(log_ns):
                    sink.diagnostics(t, msg)
                due_at = est.next_diag
            if copy is not None:
                copy(raw)
            name = raw.topic
            if name == topic:
                try:
                    sample, out = process(raw.data, log_ns)
                except DESERIALIZE_ERRORS as exc:
                    return _undecodable(reader, read, name, result.msgtype, exc)
                samples += 1
                statuses[out.status] += 1
                outcome(est, log_ns, sample, out, False)
            elif name == input_topic:
                try:
                    sample, out = process_input(raw.data, log_ns)
                except DESERIALIZE_ERRORS as exc:
                    return _undecodable(reader, read, name, INPUT_TYPE, exc)
                result.inputs += 1
                result.input_statuses[out.status] += 1
                outcome(est, log_ns, sample, out, True)
    finally:
        result.read += read
        result.samples += samples
    if result.samples == 0 and reader.damage is None:
        raise InputError(f'{reader.path}: no messages on {topic}')
    return reader.damage


def _undecodable(reader: BagReader, read: int, topic: str, msgtype: str,
                 exc: Exception) -> Damage:
    """Return the Damage of message `read` (1 first), which does not deserialize."""
    return Damage(str(reader.path), -1, f'message {read} on {topic} '
                  f'does not deserialize as {msgtype} ({exc})', read - 1)


def default_output(bag: Path, filter: str = 'estimator') -> Path:  # noqa: A002
    """Return <bag>_estimated (_aligned) next to the bag (a .mcap file: without the suffix)."""
    bag = Path(bag)
    stem = bag.stem if bag.suffix == '.mcap' else bag.name
    return bag.parent / f'{stem}{FILTER_INPUT[filter][1]}'


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Run the time-scale estimator (or the alignment filter) over a '
        "bag without DDS and write a bag with the inputs and the node's outputs.")
    parser.add_argument('bag', type=Path, help='bag directory (metadata.yaml + .mcap or '
                        '.db3) or a bare .mcap file')
    parser.add_argument('output', type=Path, nargs='?',
                        help='output bag directory (default: <bag>_estimated, with '
                        '--filter alignment <bag>_aligned)')
    parser.add_argument('--filter', choices=FILTERS, default='estimator',
                        help='the node to run: the time-scale estimator (default) or the '
                        'LED alignment node (open loop: its commands do not move the '
                        'recorded receiver)')
    parser.add_argument('--params-file', type=Path,
                        help='parameters of that node, e.g. config/owc_estimator.yaml or '
                        "config/alignment.yaml; default: the node's defaults")
    parser.add_argument('--topic', help=f'measurement topic (default {BAG_POWER_TOPIC}, with '
                        f'--filter alignment {aligner.BAG_INPUT_TOPIC}); types: '
                        + ', '.join(INPUT_TYPES))
    parser.add_argument('--input-topic', help=f"the estimator's input u ({INPUT_TYPE}); "
                        f'default {BAG_INPUT_TOPIC} if the bag has it')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing output')
    parser.add_argument('--compress', action='store_true', help='zstd-compress the chunks')
    parser.add_argument('--no-diagnostics', action='store_true',
                        help='do not write /diagnostics')
    parser.add_argument('--npz', type=Path, metavar='FILE',
                        help='analysis mode: write no bag, write the outputs as numpy arrays '
                        'to FILE (.npz; keys: see ArraySink); the estimator only')
    parser.add_argument('-q', '--quiet', action='store_true', help='only errors')
    args = parser.parse_args(argv)
    if args.npz is not None and (args.output is not None or args.filter != 'estimator'
                                 or args.compress):
        parser.error('--npz writes no bag: no output bag, --compress or --filter alignment '
                     'with it')
    if args.npz is not None and (not args.npz.name or args.npz.is_dir()):
        parser.error(f'--npz {args.npz}: a directory; give a file name, e.g. '
                     f'{args.npz / "out.npz"}')
    output = args.output or default_output(args.bag, args.filter)

    def log(line: str) -> None:
        if line.startswith('WARNING') or not args.quiet:
            print(f'{PROG}: {line}', file=sys.stderr if line.startswith('WARNING')
                  else sys.stdout, flush=True)
    if args.npz is not None:
        return _npz_main(args, log)
    try:
        res = replay(args.bag, output, params_file=args.params_file, topic=args.topic,
                     overwrite=args.overwrite, compress=args.compress,
                     diagnostics=not args.no_diagnostics, log=log, filter=args.filter,
                     input_topic=args.input_topic)
    except (BagError, ParamsError, BagTypeError, OSError) as exc:
        return error_exit(PROG, exc, args.bag)
    rate = res.read / res.seconds if res.seconds else float('nan')
    statuses = ', '.join(f'{k} {v}' for k, v in sorted(res.statuses.items()))
    if res.input_topic:
        statuses += f'; {res.inputs} inputs on {res.input_topic}'
    log(f'{res.read} messages read, {res.samples} samples on {res.topic} ({statuses}); '
        f'{sum(res.written.values())} output messages; {res.seconds:.2f} s '
        f'({rate:,.0f} msgs/s)')
    log(f'wrote {output}')
    return exit_status(PROG, res.damage, 'input damaged; the output holds what came before')


def _npz_main(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    """Analysis mode (--npz): write the arrays of replay_arrays into one .npz file."""
    path = args.npz if args.npz.suffix == '.npz' else args.npz.with_name(args.npz.name + '.npz')
    t0 = time.perf_counter()
    try:
        if path.exists() and not args.overwrite:
            raise BagExistsError(f'{path}: exists already, not overwriting (use --overwrite)')
        arrays = replay_arrays(args.bag, args.params_file, topic=args.topic,
                               input_topic=args.input_topic,
                               diagnostics=not args.no_diagnostics, log=log)
        save_npz(path, arrays)
    except (BagError, ParamsError, BagTypeError, OSError) as exc:
        return error_exit(PROG, exc, path)
    seconds = time.perf_counter() - t0
    statuses = Counter(arrays['sample.status'].tolist())
    log(f"{len(arrays['sample.log_ns'])} samples on {arrays['meta.topic']} ("
        + ', '.join(f'{k} {v}' for k, v in sorted(statuses.items()))
        + f'); {seconds:.2f} s')
    log(f'wrote {path}')
    damage = str(arrays['meta.damage'])
    if damage:
        print(f'{PROG}: input damaged; the arrays hold what came before: {damage}',
              file=sys.stderr)
        return EXIT_DAMAGED
    return 0


def save_npz(path: Path, arrays: dict) -> None:
    """Write arrays to path (.npz) whole or not at all: a temporary file, then a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    console_main()
