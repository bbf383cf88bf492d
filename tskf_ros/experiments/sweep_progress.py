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
The sweep's progress in messages read, inside each task as well as between tasks.

A task (one bag x one setting) tells how many messages it has read, at most every
`EVERY_S` seconds: in this process through a call, on a Dask worker through the worker's
event log (`Worker.log_event`, which the client receives with `Client.subscribe_topic`).
The client's bar counts the messages of every task still to run: a 1e7-message bag moves
the bar while it is read, not only when its row is done.
"""

import sys
import threading
import time
from typing import Callable, Iterable, Optional

from tskf_ros.bag.progress import bar
from tskf_ros.bag.reader import BagReader
from tskf_ros.experiments.bag_analysis import stream_size
from tskf_ros.experiments.sweep_tasks import run_task, Task

TOPIC = 'tskf-sweep-progress'
EVERY_S = 0.5       # a task's reports at most this often


def terminal() -> bool:
    """Return True where stderr is a terminal: a bar is drawn only there."""
    return sys.stderr.isatty()


class TaskProgress:
    """A task's side: counts the messages it reads and sends them, at most every EVERY_S."""

    def __init__(self, key: str, send: Callable[[dict], None]) -> None:
        self.key = key
        self.send = send
        self.unsent = 0
        self.last = time.monotonic()

    def messages(self, n: int) -> None:
        """Count n messages read; send the count if EVERY_S has passed since the last."""
        self.unsent += n
        if time.monotonic() - self.last >= EVERY_S:
            self.flush()

    def phase(self, text: str) -> None:
        """Say what the task does now (sent at once, with the messages not yet sent)."""
        self.flush(text)

    def flush(self, phase: Optional[str] = None) -> None:
        """Send the messages counted since the last report (run_task's last call)."""
        report: dict = {'key': self.key, 'messages': self.unsent}
        if phase is not None:
            report['phase'] = phase
        self.unsent, self.last = 0, time.monotonic()
        self.send(report)

    def fit_progress(self, evaluations: int, log_likelihood: float) -> None:
        """Send a fit's progress (a core.noise_fit.FitProgress) as the phase, every EVERY_S."""
        if time.monotonic() - self.last >= EVERY_S:
            self.flush(f'fitting: {evaluations} evaluations')


def run_task_reporting(task: Task) -> dict:
    """Run a task on a Dask worker, its progress sent through the worker's event log."""
    from distributed import get_worker
    worker = get_worker()
    return run_task(task, TaskProgress(task.key, lambda r: worker.log_event(TOPIC, r)))


class SweepBar:
    """
    The client's side: one bar of the messages of the tasks to run, and their rows done.

    `receive` takes a task's reports (from any thread: Dask's handlers run on the client's
    event loop); `done` a task's row.  A task's total is what its index says it reads
    (the estimator's pass, and the fit's with --fit); a report that comes after its row
    is ignored, and a row tops its task up to its total, so the bar ends full whatever
    the reports' order.
    """

    def __init__(self, tasks: Iterable[Task], enabled: bool) -> None:
        self.tasks = {t.key: t for t in tasks}
        self.totals: dict = {}
        sizes: dict = {}       # a bag is opened once however many settings it is run with
        for key, t in self.tasks.items() if enabled else ():
            where = (t.bag, t.topic, t.fit)
            if where not in sizes:
                sizes[where] = task_size(t)
            self.totals[key] = sizes[where]
        self.read = dict.fromkeys(self.tasks, 0)
        self.finished: set = set()
        self.lock = threading.Lock()
        known = list(self.totals.values())
        total = sum(known) if known and None not in known else None
        self.bar = bar(total, 'sweep', 'msg', enabled)
        self.enabled = enabled
        self.phase = ''
        self.postfix()

    def receive(self, report: dict) -> None:
        """Count a task's report of messages read (and its phase)."""
        with self.lock:
            key = report.get('key')
            if key not in self.read or key in self.finished:
                return
            n = int(report.get('messages', 0))
            self.read[key] += n
            self.bar.update(n)
            if 'phase' in report:
                self.phase = str(report['phase'])
                self.postfix()

    def done(self, key: str) -> None:
        """Count a task's row: its messages up to its total (or as read), the row done."""
        with self.lock:
            if key in self.finished or key not in self.read:
                return
            self.finished.add(key)
            rest = (self.totals.get(key) or 0) - self.read[key]
            if rest > 0:
                self.read[key] += rest
                self.bar.update(rest)
            self.phase = ''
            self.postfix()

    def postfix(self) -> None:
        text = f'{len(self.finished)}/{len(self.tasks)} rows'
        self.bar.set_postfix_str(f'{text}, {self.phase}' if self.phase else text)

    def close(self) -> None:
        self.bar.close()


def task_size(task: Task) -> Optional[int]:
    """Return the messages a task reads (None if a bag's index does not say or it fails)."""
    try:
        reader = BagReader(task.bag)         # its index read once for both passes
        size = stream_size(task.bag, topic=task.topic, reader=reader)
        fit = (stream_size(task.bag, topic=task.topic, truth=False, reader=reader)
               if task.fit else 0)
    except Exception:  # noqa: B902 - the task itself reports a bag it cannot use
        return None
    return None if size is None or fit is None else size + fit
