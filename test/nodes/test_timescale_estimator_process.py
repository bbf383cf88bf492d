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

"""timescale_estimator as a process: its estimates over DDS, and bad parameters in one line."""

import time

from diagnostic_msgs.msg import DiagnosticArray
from node_helpers import node_process, REPO, run_node, stop, TIMEOUT
import numpy as np
import pytest
import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Illuminance

from tskf_ros.core.linear_models import owc, run_filter
from tskf_ros.core.time_scales import discrete
from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.tools import demo_collector
from tskf_ros.tools.demo_collector import arrays, Collector, wait_for

# s: a sample the estimator process has not answered within this is published again (the
# node drops the repeat as a duplicate): best effort across processes may lose one
RESEND = 0.5


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


@pytest.mark.slow
def test_estimator_in_another_process(ros_context, executor_kind, tmp_path):
    log = (tmp_path / 'estimator.log').open('w+')
    # /diagnostics every 0.1 s: its arrival tells that the node has matched our readers
    proc = node_process('timescale_estimator', '--executor', executor_kind, '--ros-args',
                        '--params-file', str(REPO / 'config' / 'owc_estimator.yaml'),
                        '-p', 'diagnostic_updater.period:=0.1',
                        '-r', 'measurement:=received_power', log=log)
    client = rclpy.create_node('client', context=ros_context)
    collector = Collector(context=ros_context)
    # created after the collector's estimate subscriptions: we announce our readers in
    # creation order on one reliable discovery stream, and the node matches each as it
    # reads it; once its /diagnostics writer has matched this later reader (a message
    # arrived), its estimate writers have matched the earlier ones, so no estimate is
    # published before our readers are there to get it
    diagnostics = []
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append,
                               QoSProfile(depth=10))
    pub = client.create_publisher(Illuminance, 'received_power', QoSProfile(depth=100))
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(client)
    executor.add_node(collector)
    stamps = np.array([1.0, 2.0, 3.0, 6.0, 7.0, 8.0, 8.5, 9.0, 13.0, 14.0])
    y = np.random.default_rng(4).normal(180.0, 10.0, stamps.size)
    predicted = collector.record.predicted
    failure = None
    try:
        spin_until(executor, lambda: pub.get_subscription_count() >= 2
                   and collector.peers_ready() and any(
                       s.name.startswith('timescale_estimator') for m in diagnostics
                       for s in m.status),
                   lambda: 'the estimator process (its input matched: '
                   f'{pub.get_subscription_count() >= 2}, its outputs seen: '
                   f'{collector.peers_ready()}, /diagnostics from it: {len(diagnostics)}; '
                   f'exit status {proc.poll()})')
        # one sample at a time, each until it is estimated: our writer may be matched by
        # the node a little after we see its reader, and best effort across processes may
        # lose a sample; a repeat is a duplicate, which the node drops (and says so)
        for t, v in zip(stamps, y):
            stamp = int(t * NS)
            msg = conversions.power_to_msg(stamp, v, 100.0)
            deadline = time.monotonic() + TIMEOUT
            while stamp not in predicted:
                assert time.monotonic() < deadline, \
                    f'the estimator never answered the sample at {t} s (exit {proc.poll()})'
                pub.publish(msg)
                demo_collector.spin_until(executor, lambda: stamp in predicted, RESEND)
        spin_until(executor, lambda: len(collector.record.corrected) == stamps.size - 1,
                   lambda: f'{stamps.size - 1} corrected estimates (got '
                   f'{len(collector.record.corrected)})')
    except (AssertionError, TimeoutError) as error:
        failure = error
    finally:
        executor.shutdown()
        client.destroy_node()
        collector.destroy_node()
        out = stop(proc, log)
        log.close()
    # the node's own output says where it was (a wait that failed here says only what we saw)
    assert failure is None, f'{failure}\nthe estimator process printed:\n{out}'
    assert proc.returncode == 0, out
    assert 'rejected (duplicate)' in out or 'WARN' not in out
    ref = run_filter(owc(), discrete(stamps), y[:, None])
    tp, xp = arrays(predicted)
    np.testing.assert_array_equal(tp, (stamps * NS).astype(np.int64))
    np.testing.assert_allclose(xp, ref.x_pred[:, 0], rtol=0, atol=1e-9)
    tc, xc = arrays(collector.record.corrected)
    np.testing.assert_array_equal(tc, (stamps[:-1] * NS).astype(np.int64))
    np.testing.assert_allclose(xc, ref.x_corr[:-1, 0], rtol=0, atol=1e-9)


def test_bad_yaml_parameters_exit_1():
    code, out = run_node('timescale_estimator', '--ros-args', '-p', 'Q:=[1.0, 2.0]')
    assert code == 1 and 'Q must have 1 entries' in out
