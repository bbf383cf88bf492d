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

"""The replay loop: every message of a bag in storage order through the node's session."""

from contextlib import contextmanager
import gc
import os
from pathlib import Path
import time
from typing import Callable, Iterator, NamedTuple, Optional, Union

import numpy as np

from numpy.typing import NDArray

from tskf_ros.bag.message_types import qos_from_rclpy, typestore
from tskf_ros.bag.outputs import check_outputs
from tskf_ros.bag.progress import DeferredInterrupt, wrap
from tskf_ros.bag.reader import BagReader, Damage, MessageBlock, RawMessage
from tskf_ros.bag.replay.adapters import (AnyConfig, OfflineAligner, OfflineEstimator,
                                          UNDECODABLE)
from tskf_ros.bag.replay.array_sink import ArraySink
from tskf_ros.bag.replay.columns import ColumnStore
from tskf_ros.bag.replay.gathered import GATHER, Gathered
from tskf_ros.bag.replay.model_check import check_model
from tskf_ros.bag.replay.rts_replay import SmoothingRecorder
from tskf_ros.bag.replay.sinks import BagSink, Collector, ReplayResult, Sink, SMOOTHED_TOPIC
from tskf_ros.bag.replay.topic_choice import choose_input_topic, choose_topic, InputError
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages import estimator_interface as estimator
from tskf_ros.messages.estimator_interface import (BAG_POWER_TOPIC, DIAGNOSTICS_TOPIC,
                                                   DIAGNOSTICS_TYPE, INPUT_TYPE, load_config)

__all__ = ['add_topics', 'array_sink', 'FILTER_INPUT', 'FILTERS', 'prepare', 'replay',
           'replay_arrays', 'run_replay']

PathLike = Union[str, os.PathLike]
Log = Callable[[str], None]
FILTERS = ('estimator', 'alignment')
# filter -> (default input topic, suffix of the default output)
FILTER_INPUT = {'estimator': (BAG_POWER_TOPIC, '_estimated'),
                'alignment': (aligner.BAG_INPUT_TOPIC, '_aligned')}


# the replay loop calls its check every CHECK_EVERY + 1 messages (a power of two, less one)
CHECK_EVERY = 1023


def _quiet(line: str) -> None:
    """Log nothing."""


def _nothing() -> None:
    """Do nothing."""


def prepare(bag: PathLike, config: Union[AnyConfig, PathLike, None], topic: Optional[str],
            filter: str, input_topic: Optional[str], log: Log,  # noqa: A002
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
        check_model(reader, result.input_topic, config.session.model)
    for line in result.assumptions:
        log(line)
    est = (OfflineAligner if aligning else OfflineEstimator)(config, result.msgtype)
    return reader, est, result


def replay(bag: PathLike, output: Optional[PathLike] = None, *,
           params_file: Optional[PathLike] = None, topic: Optional[str] = None,
           overwrite: bool = False, compress: bool = False, diagnostics: bool = True,
           log: Log = _quiet,
           filter: str = 'estimator',  # noqa: A002 (the CLI's --filter)
           input_topic: Optional[str] = None, smooth: bool = False,
           progress: bool = False) -> ReplayResult:
    """
    Run the estimator over `bag`; write `output` (a new bag) or, if None, collect in memory.

    smooth=True (the estimator, into a bag) also writes the RTS-smoothed estimates x(t|T)
    of every segment on SMOOTHED_TOPIC once the bag has been read (bag/replay/rts_replay).

    filter='alignment' runs the alignment node's session instead (open loop: its commands
    do not move the recorded receiver).
    input_topic: the estimator's input u (default /input if present; see choose_input_topic).
    In memory, `result.outputs` holds (topic, log time, rclpy message or the input's
    RawMessage) in order.  progress: a bar of the messages read (on a terminal).

    Raises BagError / ParamsError / BagTypeError before anything is written if the bag or
    the parameters cannot be used.  Damage met while reading stops the replay; what came
    before is processed and written, and `result.damage` says where it stopped.
    """
    t0 = time.perf_counter()
    if output is not None:
        _check_output(Path(bag), Path(output), overwrite)
    if smooth and (filter != 'estimator' or output is None):
        raise ValueError('smoothing is for the estimator written into a bag (or arrays)')
    with DeferredInterrupt() as interrupt:
        reader, est, result = prepare(bag, params_file, topic, filter, input_topic, log)
        if output is None:
            result.damage = run_replay(reader, est, Collector(result), result, diagnostics,
                                       progress, interrupt.check)
        else:
            _write_bag(reader, est, result, Path(output), overwrite, compress, diagnostics,
                       smooth, progress, interrupt, log)
    result.seconds = time.perf_counter() - t0
    return result


def _write_bag(reader: BagReader, est: OfflineEstimator, result: ReplayResult, output: Path,
               overwrite: bool, compress: bool, diagnostics: bool, smooth: bool,
               progress: bool, interrupt: DeferredInterrupt, log: Log) -> None:
    """Replay into a new bag at `output`: whole, or (on any error or Ctrl-C) not at all."""
    writer = BagWriter(output, overwrite=overwrite, compress=compress, disposable=True)
    writer.open()
    try:
        add_topics(writer, reader, est, diagnostics, log)
        if isinstance(est, OfflineAligner):
            writer.set_custom_data('tskf_ros.open_loop', aligner.OPEN_LOOP_NOTE)
        smoother = None
        if smooth:
            smoother = SmoothingRecorder(est.config.session)
            writer.add_topic(SMOOTHED_TOPIC, estimator.ESTIMATE_TYPE,
                             qos=[qos_from_rclpy(est.output_topics()[0][2])])
        sink = BagSink(writer, result, smoother)
        with _gc_paused(not isinstance(est, OfflineAligner)):
            result.damage = run_replay(reader, est, sink, result, diagnostics, progress,
                                       interrupt.check)
            sink.finish(est)
        if result.damage is not None:
            writer.set_custom_data('tskf_ros.input_damage', str(result.damage))
        interrupt.check()       # the last moment a Ctrl-C leaves nothing
        writer.close()
    except BaseException:
        writer.abort()
        raise


def replay_arrays(bag: PathLike, config: Union[AnyConfig, PathLike, None] = None, *,
                  topic: Optional[str] = None, input_topic: Optional[str] = None,
                  diagnostics: bool = True, log: Log = _quiet,
                  smooth: bool = False, progress: bool = False) -> dict[str, NDArray]:
    """
    Run the estimator over `bag` and return its outputs as numpy arrays; write nothing.

    config: a NodeConfig (estimator_interface.load_config / parameters_to_config), a
    parameter file, or None for the node's defaults.  The keys (see ArraySink) hold what
    the output bag's topics hold, one row per message; 'meta.damage' is '' or the damage
    that stopped the reading (the rows are what came before it).  smooth=True adds the
    RTS-smoothed estimates (estimate/smoothed.*).  Raises as replay().
    """
    with DeferredInterrupt() as interrupt:
        reader, est, result = prepare(bag, config, topic, 'estimator', input_topic, log)
        sink = array_sink(reader, est, result, smooth)
        with _gc_paused():
            result.damage = run_replay(reader, est, sink, result, diagnostics, progress,
                                       interrupt.check)
            interrupt.check()
            return sink.arrays(result)


def array_sink(reader: BagReader, est: OfflineEstimator, result: ReplayResult,
               smooth: bool, store: Optional[ColumnStore] = None) -> ArraySink:
    """Return the ArraySink of a replay (its columns sized for the bag's measurements)."""
    count = reader.topics[result.topic].count if result.topic in reader.topics else None
    return ArraySink(est, SmoothingRecorder(est.config.session) if smooth else None,
                     store=store, inputs=bool(result.input_topic), capacity=count or 0)


@contextmanager
def _gc_paused(pause: bool = True) -> Iterator[None]:
    """
    Pause Python's cyclic garbage collector (if it runs) for the estimator's replay loop.

    The loop makes no reference cycles; the collector would only rescan the rows kept
    (doc/design/bags.md).  It is restored on the way out, whatever happens.
    """
    was = pause and gc.isenabled()
    if was:
        gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def add_topics(writer: BagWriter, reader: BagReader, est: OfflineEstimator,
               diagnostics: bool, log: Log) -> None:
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
    check_outputs([output], [bag])
    BagWriter(output, overwrite=overwrite).check_target()


def run_replay(reader: BagReader, est: OfflineEstimator, sink: Sink, result: ReplayResult,
               diagnostics: bool, progress: bool = False,
               check: Callable[[], None] = _nothing) -> Optional[Damage]:
    """
    Read, estimate, hand the outputs to the sink; return the damage that stopped it.

    The estimator's measurements are gathered up to the next input u, /diagnostics message
    due or GATHER messages and taken by the session in runs (EstimatorSession.add_many);
    the sink gets every message and outcome in storage order, as one at a time, and first
    (at the first message's log time) what the node publishes as it starts.  progress: a
    bar of the messages read (a terminal only).  check: called every CHECK_EVERY messages
    (DeferredInterrupt.check: a Ctrl-C stops the replay there).
    """
    topic, input_topic = result.topic, result.input_topic
    process_input = est.process_input
    copy = sink.copy if sink.copies else None
    outcome = sink.outcome
    statuses = result.statuses
    # the log time from which est.diagnostics_due may have something (None: never)
    due_at = -1 if diagnostics else None
    read = 0                    # result.read, kept in a local
    gathered = Gathered(est.read_sample)
    gather = est.batched
    # runs of measurements read at once (MessageBlock) where nothing is copied
    blocks = gather and copy is None
    messages: Iterator = (_decoded(reader.message_blocks(), topic, est.read_block)
                          if blocks else reader.messages())
    if progress:
        counts = [i.count for i in reader.topics.values()]
        total = sum(counts) if all(c is not None for c in counts) else None
        messages = wrap(messages, total, 'replaying', 'msg',
                        weight=lambda item: len(item.logs) if item.__class__ is Decoded else 1)

    # what the node publishes as it starts, written at the first message's log time
    start: Optional[Callable[[], list]] = est.start_messages

    def flush() -> None:
        if gathered.pending or gathered.held:
            gathered.hand_over(est, sink, statuses)
    try:
        for raw in messages:
            if raw.__class__ is Decoded:
                if start is not None:
                    for name, msg in start():
                        sink.message(name, int(raw.logs[0]), msg)
                    start = None
                n = len(raw.logs)
                if (read + n) >> 10 != read >> 10:
                    check()
                read += n
                i = 0
                while i < n:
                    j = n
                    if due_at is not None:
                        late = np.flatnonzero(raw.logs[i:] >= due_at)
                        j = i + int(late[0]) if len(late) else n
                    while i < j:
                        k = min(j, i + GATHER - len(gathered.held) - gathered.pending)
                        gathered.add_block(raw.stamps[i:k], raw.values[i:k],
                                           raw.variances[i:k], raw.logs[i:k])
                        i = k
                        if len(gathered.held) + gathered.pending >= GATHER:
                            flush()
                    if j < n:
                        log_j = int(raw.logs[j])
                        flush()
                        for t, msg in est.diagnostics_due(log_j):
                            sink.diagnostics(t, msg)
                        due_at = est.next_diag
                continue
            read += 1
            if not read & CHECK_EVERY:
                check()
            log_ns = raw.log_time_ns
            if start is not None:
                for name, msg in start():
                    sink.message(name, log_ns, msg)
                start = None
            if due_at is not None and log_ns >= due_at:
                flush()
                for t, msg in est.diagnostics_due(log_ns):
                    sink.diagnostics(t, msg)
                due_at = est.next_diag
            name = raw.topic
            if gather and name != input_topic:
                try:
                    gathered.add(raw, name == topic, copy is not None)
                except UNDECODABLE as exc:
                    flush()
                    return _undecodable(reader, read, name, result.msgtype, exc)
                if len(gathered.held) + gathered.pending >= GATHER:
                    flush()
                continue
            flush()
            if copy is not None:
                copy(raw)
            if name == topic:
                try:
                    sample, out = est.process(raw.data, log_ns)
                except UNDECODABLE as exc:
                    return _undecodable(reader, read, name, result.msgtype, exc)
                result.samples += 1
                statuses[out.status] += 1
                outcome(est, log_ns, sample, out, False)
            elif name == input_topic:
                try:
                    sample, out = process_input(raw.data, log_ns)
                except UNDECODABLE as exc:
                    return _undecodable(reader, read, name, INPUT_TYPE, exc)
                result.inputs += 1
                result.input_statuses[out.status] += 1
                outcome(est, log_ns, sample, out, True)
        flush()
    finally:
        messages.close()
        result.read += read
        result.samples += gathered.samples
    if result.samples == 0 and reader.damage is None:
        raise InputError(f'{reader.path}: no messages on {topic}')
    return reader.damage


class Decoded(NamedTuple):
    """A MessageBlock of measurements, decoded (adapters.block_reader)."""

    stamps: NDArray[np.int64]
    values: NDArray[np.float64]
    variances: NDArray[np.float64]
    logs: NDArray[np.int64]


def _decoded(items: Iterator[Union[RawMessage, MessageBlock]], topic: str,
             read_block: Callable) -> Iterator[Union[RawMessage, Decoded]]:
    """Yield the blocks of `topic` that read_block decodes as Decoded, all else one by one."""
    for item in items:
        if item.__class__ is MessageBlock:
            got = read_block(item.payloads, item.log_times) if item.topic == topic else None
            if got is None:
                yield from item.messages()
            else:
                yield Decoded(*got, item.log_times)
        else:
            yield item


def _undecodable(reader: BagReader, read: int, topic: str, msgtype: str,
                 exc: Exception) -> Damage:
    """Return the Damage of message `read` (1 first), which does not deserialize."""
    return Damage(str(reader.path), -1, f'message {read} on {topic} '
                  f'does not deserialize as {msgtype} ({exc})', read - 1)
