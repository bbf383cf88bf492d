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
"""The estimator's outputs as numpy columns: in memory (replay_arrays) or on disk (--npz)."""

from typing import Any, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.bag.reader import RawMessage
from tskf_ros.bag.replay.adapters import AnyOutcome, OfflineEstimator
from tskf_ros.bag.replay.columns import CATEGORY, ColumnStore, MemoryStore, Table
from tskf_ros.bag.replay.rts_replay import SmoothingRecorder
from tskf_ros.bag.replay.sinks import ReplayResult, SMOOTHED_TOPIC
from tskf_ros.core.units import NS
from tskf_ros.owc.session.outcome import Run

__all__ = ['ARRAY_NAMES', 'ArraySink']

# (kind, revised) -> the name of its arrays: one set per kind of estimate
ARRAY_NAMES = {('predicted', False): 'estimate/predicted',
               ('corrected', False): 'estimate/corrected',
               ('mu', False): 'estimate/mu',
               ('predicted', True): 'estimate/revised/predicted',
               ('corrected', True): 'estimate/revised/corrected',
               ('mu', True): 'estimate/revised/mu'}
_I8, _F8 = np.int64, np.float64


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

    The rows go to `store` (columns.py) a block at a time: a MemoryStore (`arrays()`), or
    a FileStore that writes the .npz.  inputs: whether the bag has an input u topic (the
    input.* keys); capacity: the rows expected per table (the measurements in the bag).
    """

    copies = False      # copy() does nothing: the loop need not call it

    def __init__(self, est: OfflineEstimator, smoother: Optional[SmoothingRecorder] = None,
                 *, store: Optional[ColumnStore] = None, inputs: bool = True,
                 capacity: int = 0) -> None:
        self.smoother = smoother
        self.n = n = len(est.config.session.model.state_names)
        self.store = store = MemoryStore() if store is None else store
        self.samples = Table(store, 'sample', [
            ('log_ns', _I8, ()), ('stamp_ns', _I8, ()), ('value', _F8, ()),
            ('variance', _F8, ()), ('status', CATEGORY, ()), ('reason', CATEGORY, ())],
            capacity)
        self.inputs = None if not inputs else Table(store, 'input', [
            ('log_ns', _I8, ()), ('stamp_ns', _I8, ()), ('status', CATEGORY, ())])
        self.estimates: dict[tuple, Table] = {}
        for key, name in ARRAY_NAMES.items():
            size = 0 if key[1] else capacity
            if key[0] == 'mu':
                columns = [('log_ns', _I8, ()), ('stamp_ns', _I8, ()), ('sigma_ns', _I8, ()),
                           ('mu', _F8, ())]
            else:
                columns = [('log_ns', _I8, ()), ('stamp_ns', _I8, ()), ('x', _F8, (n,)),
                           ('P', _F8, (n, n))]
            self.estimates[key] = Table(store, name, columns, size)
        self.diag: list[tuple[int, int, str]] = []   # one per diagnostics period: few

    def copy(self, raw: RawMessage) -> None:
        """Keep nothing of the inputs."""

    def outcome(self, est: OfflineEstimator, log_ns: int, sample: tuple, out: AnyOutcome,
                is_input: bool) -> None:
        """Keep a row of the sample and a row of each estimate and jump."""
        if is_input:
            if self.inputs is not None:
                self.inputs.row((log_ns, sample[0], out.status))
        else:
            self.samples.row((log_ns, *sample, out.status, out.reason))
        tables = self.estimates
        for e in out.estimates:
            tables[e.kind, e.revised].row((log_ns, e.stamp_ns, e.x, e.P))
        if self.smoother is not None:
            self.smoother.outcome(out)
        for j in out.jumps:
            tables['mu', j.revised].row((log_ns, j.stamp_ns, j.sigma_ns,
                                         (j.sigma_ns - j.stamp_ns) / NS))

    def message(self, topic: str, log_ns: int, msg: Any) -> None:
        """Keep nothing: the estimator publishes no message outside an outcome."""

    def run_rows(self, run: Run, logs: NDArray[np.int64], stamps: NDArray[np.int64],
                 values: NDArray[np.float64], variances: NDArray[np.float64]) -> None:
        """Keep the rows `outcome` keeps for each sample of a run (all accepted, in order)."""
        self.samples.block(logs, stamps, values, variances, 'accepted', '')
        tables = self.estimates
        previous = run.previous_ns
        tables['corrected', False].block(logs, previous, run.x_corrected, run.P_corrected)
        tables['predicted', False].block(logs, run.stamps_ns, run.x_predicted,
                                         run.P_predicted)
        tables['mu', False].block(logs, previous, run.stamps_ns,
                                  (run.stamps_ns - previous) / NS)

    def diagnostics(self, stamp_ns: int, msg: Any) -> None:
        """Keep a row of the /diagnostics message: the level and message of its worst task."""
        levels = [s.level[0] if isinstance(s.level, bytes) else int(s.level)
                  for s in msg.status]
        worst = max(range(len(levels)), key=levels.__getitem__)
        self.diag.append((stamp_ns, levels[worst],
                          f'{msg.status[worst].name}: {msg.status[worst].message}'))

    def flush(self) -> None:
        """Hand every row kept on to the store."""
        for table in (self.samples, self.inputs, *self.estimates.values()):
            if table is not None:
                table.flush()

    def extras(self, result: ReplayResult) -> dict[str, NDArray]:
        """Return the arrays made at the end: diagnostics, smoothed, meta."""
        out = {}
        logs, levels, messages = zip(*self.diag) if self.diag else ((), (), ())
        out['diagnostics.log_ns'] = np.array(logs, dtype=_I8)
        out['diagnostics.level'] = np.array(levels, dtype=np.int8)
        out['diagnostics.message'] = np.array(messages, dtype=str)
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

    def arrays(self, result: ReplayResult) -> dict[str, NDArray]:
        """Return the numpy arrays of a sink in memory (keys: see the class doc)."""
        if not isinstance(self.store, MemoryStore):
            raise TypeError('arrays() is for a sink in memory; a FileStore writes the .npz')
        self.flush()
        out = self.store.arrays()
        out.update(self.extras(result))
        return out
