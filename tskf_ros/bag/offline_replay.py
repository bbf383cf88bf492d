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
from dataclasses import dataclass, field
import os
from pathlib import Path
import sys
import time
from typing import Callable, Optional

from rclpy.serialization import deserialize_message, serialize_message

from tskf_ros.bag.message_types import BagTypeError, message_class, qos_from_rclpy, typestore
from tskf_ros.bag.reader import BagError, BagReader, Damage, error_exit, exit_status
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
from tskf_ros.owc.estimator_session import EstimatorSession

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


class OfflineEstimator:
    """The live node's work on one message at a time, without DDS or a clock."""

    interface = estimator   # the node's module in tskf_ros.messages
    session_class: type = EstimatorSession

    def __init__(self, config: NodeConfig, msgtype: str) -> None:
        self.config = config
        self.session = self.session_class(config.session)
        self.cls = message_class(msgtype)
        self.extract = extractor(msgtype)
        self.period_ns = int(round(config.diagnostics_period * NS))
        self.next_diag: Optional[int] = None

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

    def process(self, data: bytes, log_ns: int) -> tuple[str, list]:
        """Deserialize one measurement and run it; return (status, [(topic, msg)])."""
        msg = deserialize_message(data, self.cls)
        stamp_ns, value, variance = self.extract(msg, log_ns)
        out = self.session.add(stamp_ns, value, variance, now_ns=log_ns)
        return out.status, bag_outcome_messages(out, self.config)

    def process_input(self, data: bytes, log_ns: int) -> tuple[str, list]:
        """Deserialize one input u and run it; return (status, [(topic, msg)])."""
        msg = deserialize_message(data, message_class(INPUT_TYPE))
        out = self.session.add_input(*input_from_msg(msg, self.session))
        return out.status, bag_outcome_messages(out, self.config)


class OfflineAligner(OfflineEstimator):
    """The live alignment node's work on one message at a time, without DDS or a clock."""

    interface = aligner
    session_class = AlignmentSession

    def output_topics(self) -> list:
        """Return the (topic, type, rclpy QoS) of every output but /diagnostics."""
        return [(name, aligner.OUTPUT_TYPES[key], aligner.output_qos(self.config, key))
                for key, name in aligner.BAG_OUTPUT_TOPICS.items()]

    def process(self, data: bytes, log_ns: int) -> tuple[str, list]:
        """Deserialize one intensity sample and run it; return (status, [(topic, msg)])."""
        msg = deserialize_message(data, self.cls)
        stamp_ns, volts, _ = self.extract(msg, log_ns)
        out = self.session.add(stamp_ns, volts, now_ns=log_ns)
        return out.status, aligner.bag_outcome_messages(out, self.config)


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

    Raises BagError / ParamsError / BagTypeError before anything is written if the bag or
    the parameters cannot be used.  Damage met while reading stops the replay; what came
    before is processed and written, and `result.damage` says where it stopped.
    """
    t0 = time.perf_counter()
    if filter not in FILTERS:
        raise ValueError(f'filter must be one of {FILTERS}, got {filter!r}')
    if output is not None:
        _check_output(Path(bag), Path(output), overwrite)
    reader = BagReader(bag)
    aligning = filter == 'alignment'
    config = (aligner.load_config if aligning else load_config)(params_file)
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
    writer = None
    store = typestore()
    if output is not None:
        writer = BagWriter(output, overwrite=overwrite, compress=compress)
        writer.open()
    try:
        if writer is not None:
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
            if aligning:
                writer.set_custom_data('tskf_ros.open_loop', aligner.OPEN_LOOP_NOTE)
        damage = _run(reader, est, writer, result, diagnostics)
        if damage is not None:
            result.damage = damage
            if writer is not None:
                writer.set_custom_data('tskf_ros.input_damage', str(damage))
        if writer is not None:
            writer.close()
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    result.seconds = time.perf_counter() - t0
    return result


def _check_output(bag: Path, output: Path, overwrite: bool) -> None:
    """Raise a BagError if `output` cannot be written (before anything is read or made)."""
    out, src = output.resolve(), bag.resolve()
    if out == src or src.is_relative_to(out) or out.is_relative_to(src):
        raise BagExistsError(f'{output}: is (or holds, or is inside) the input bag {bag}; '
                             'give another output')
    BagWriter(output, overwrite=overwrite).check_target()


def _run(reader: BagReader, est: OfflineEstimator, writer: Optional[BagWriter],
         result: ReplayResult, diagnostics: bool) -> Optional[Damage]:
    """Read, estimate, write; return the damage that stopped the reading, if any."""
    topic = result.topic
    collect = writer is None
    for raw in reader.messages():
        result.read += 1
        log_ns = raw.log_time_ns
        if diagnostics:
            for t, msg in est.diagnostics_due(log_ns):
                _emit(writer, result, DIAGNOSTICS_TOPIC, t, msg, collect)
        if writer is not None and writer.has_topic(raw.topic):
            writer.write(raw.topic, log_ns, raw.data)
        process, msgs = None, []
        if raw.topic == result.input_topic:
            process, msgtype = est.process_input, INPUT_TYPE
        elif raw.topic == topic:
            process, msgtype = est.process, result.msgtype
        if process is not None:
            try:
                status, msgs = process(raw.data, log_ns)
            except DESERIALIZE_ERRORS as exc:
                return Damage(str(reader.path), -1, f'message {result.read} on {raw.topic} '
                              f'does not deserialize as {msgtype} ({exc})', result.read - 1)
        if collect:
            result.outputs.append((raw.topic, log_ns, raw))
        if process is None:
            continue
        if process == est.process:
            result.samples += 1
            result.statuses[status] += 1
        else:
            result.inputs += 1
            result.input_statuses[status] += 1
        for name, msg in msgs:
            _emit(writer, result, name, log_ns, msg, collect)
    if result.samples == 0 and reader.damage is None:
        raise InputError(f'{reader.path}: no messages on {topic}')
    return reader.damage


def _emit(writer: Optional[BagWriter], result: ReplayResult, topic: str, log_ns: int,
          msg: object, collect: bool) -> None:
    result.written[topic] += 1
    if collect:
        result.outputs.append((topic, log_ns, msg))
    else:
        writer.write(topic, log_ns, serialize_message(msg))


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
    parser.add_argument('-q', '--quiet', action='store_true', help='only errors')
    args = parser.parse_args(argv)
    output = args.output or default_output(args.bag, args.filter)

    def log(line: str) -> None:
        if line.startswith('WARNING') or not args.quiet:
            print(f'{PROG}: {line}', file=sys.stderr if line.startswith('WARNING')
                  else sys.stdout, flush=True)
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


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    console_main()
