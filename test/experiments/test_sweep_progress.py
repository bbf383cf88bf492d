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

"""The sweep's progress in messages: within a task, in this process and from Dask workers."""

from pathlib import Path
import time

from mcap.reader import make_reader
import pytest
from tskf_ros.experiments import bag_analysis, sweep, sweep_progress
from tskf_ros.experiments.sweep_progress import SweepBar, TaskProgress
from tskf_ros.experiments.sweep_tasks import build_tasks

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / 'bags' / 'owc_cai_td_1hz'
DROGUE = REPO / 'bags' / 'drogue'
PARAMS = REPO / 'config' / 'owc_estimator.yaml'
JOINT_STATE = 'sensor_msgs/msg/JointState'
DEADLINE_S = 60.0


def counted(bag: Path, measurement: str, more: tuple = ()) -> int:
    """Count a bag's messages on its measurement, input and JointState topics (mcap's reader)."""
    (path,) = bag.glob('*.mcap')
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    topics = {measurement, *more} | {c.topic for c in summary.channels.values()
                                     if summary.schemas[c.schema_id].name == JOINT_STATE}
    return sum(n for i, n in summary.statistics.channel_message_counts.items()
               if summary.channels[i].topic in topics)


class Recorder(SweepBar):
    """The sweep's bar, keeping the reports it receives."""

    reports: list = []

    def receive(self, report: dict) -> None:
        Recorder.reports.append(dict(report))
        super().receive(report)


def test_the_size_is_what_the_index_says_read_stream_reads():
    assert bag_analysis.stream_size(SAMPLE) == counted(SAMPLE, '/received_power') == 589
    assert bag_analysis.stream_size(SAMPLE, truth=False) == 288
    assert bag_analysis.stream_size(DROGUE) == counted(DROGUE, '/received_power', ('/input',))


def test_a_task_sends_what_it_counted_and_nothing_twice():
    sent: list = []
    p = TaskProgress('k', sent.append)
    for n in (3, 5, 4096, 1):
        p.messages(n)
    p.phase('fitting')
    p.messages(7)
    p.flush()
    assert sum(r['messages'] for r in sent) == 3 + 5 + 4096 + 1 + 7
    assert [r['phase'] for r in sent if 'phase' in r] == ['fitting']
    assert all(r['key'] == 'k' for r in sent)


def test_the_bar_ends_at_its_total_whatever_the_reports_order():
    tasks = build_tasks([str(SAMPLE)], PARAMS, [('R', [[1.0], [100.0]])])
    bar = SweepBar(tasks, enabled=True)
    a, b = (t.key for t in tasks)
    assert bar.totals == {a: 589, b: 589}
    bar.receive({'key': a, 'messages': 100})
    bar.done(a)                                         # tops a up to its 589
    bar.receive({'key': a, 'messages': 100})            # late: ignored
    bar.receive({'key': 'not a task', 'messages': 5})   # ignored
    bar.receive({'key': b, 'messages': 589, 'phase': 'reading'})
    bar.done(b)
    bar.close()
    assert bar.read == {a: 589, b: 589}
    assert bar.finished == {a, b}


@pytest.mark.parametrize('fit', [False, True])
def test_a_sequential_sweep_reports_the_messages_as_they_are_read(tmp_path, monkeypatch, fit):
    monkeypatch.setattr(bag_analysis, 'TICK', 64)
    monkeypatch.setattr(sweep_progress, 'EVERY_S', 0.0)
    monkeypatch.setattr(sweep, 'terminal', lambda: True)
    monkeypatch.setattr(sweep, 'SweepBar', Recorder)
    Recorder.reports = []
    res = sweep.sweep([str(SAMPLE)], out=tmp_path / 't.csv', params_file=PARAMS, workers=0,
                      progress=True, fit=fit)
    assert res.errors == 0 and len(res.evaluated) == 1
    messages = [r['messages'] for r in Recorder.reports if r['messages']]
    # the estimator's pass in reports of 64 messages (9 of them, then the last 13), and
    # with the fit its read as well
    assert sum(messages) == 589 + (288 if fit else 0)
    assert messages[:9] == [64] * 9
    phases = [r['phase'] for r in Recorder.reports if 'phase' in r]
    assert ('reading for the fit' in phases) == fit


def test_a_dask_worker_reports_through_its_event_log(tmp_path, monkeypatch):
    distributed = pytest.importorskip('distributed')
    task = build_tasks([str(SAMPLE)], PARAMS, [])[0]
    received: list = []
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, host='127.0.0.1',
                                  dashboard_address=None, processes=True) as cluster, \
            distributed.Client(cluster) as client:
        client.subscribe_topic(sweep_progress.TOPIC, lambda event: received.append(event[1]))
        row = client.submit(sweep_progress.run_task_reporting, task, pure=False).result(
            timeout=DEADLINE_S)
        deadline = time.monotonic() + DEADLINE_S
        while sum(r['messages'] for r in received) < 589 and time.monotonic() < deadline:
            time.sleep(0.05)
    assert row['error'] == ''
    assert sum(r['messages'] for r in received) == 589
    assert {r['key'] for r in received} == {task.key}
