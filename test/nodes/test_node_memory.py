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
The estimator node under a flood keeps no per-message memory: what it retains stays bounded.

Before, the input monitor kept the receipt time of each of the last 100 000 messages (a
deque the live node filled and only the diagnostics trimmed), so the node's memory grew by
tens of bytes per message until that cap (about 4 MB; 50 s of a 2 kHz flood).  Now the
diagnostic tasks keep counters only.  A bounded in-process flood through the node's own
callback: after the history is full, another batch of messages must not grow what Python
allocated (tracemalloc) by more than a small constant; nothing is timed.
"""

import tracemalloc

from rclpy.parameter import Parameter

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator

T0 = 1_700_000_000 * NS
BATCH = 3000                # messages per batch (history_size is 1000)
# bytes a batch may leave allocated: far below BATCH x the ~36 bytes one retained receipt
# time (an int in a deque) took
SLACK = 32_000


def test_a_flood_leaves_the_nodes_memory_bounded(loop, ros_context):
    _, _, nodes = loop
    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('period', value=0.0005), Parameter('diagnostic_updater.period', value=3600.0),
        Parameter('status_period', value=0.0)])
    nodes.append(node)
    msgs = [conversions.power_to_msg(T0 + k * NS // 2000, 165.0 + (k % 7) - 3.0)
            for k in range(3 * BATCH)]

    def flood(batch):
        for msg in msgs[batch * BATCH:(batch + 1) * BATCH]:
            node._on_measurement(msg)

    flood(0)                                     # fills the history and every cache
    node.diagnostics_message(node.get_clock().now().nanoseconds)
    tracemalloc.start()
    try:
        flood(1)
        node.diagnostics_message(node.get_clock().now().nanoseconds)
        before = tracemalloc.get_traced_memory()[0]
        flood(2)
        node.diagnostics_message(node.get_clock().now().nanoseconds)
        after = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert node.session.stats.received == 3 * BATCH
    assert node.session.stats.accepted == 3 * BATCH
    assert after - before < SLACK, f'{after - before} bytes retained by {BATCH} messages'
