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

"""The power_meter_simulator node: the seeded stream with its gaps, and 1 kHz."""

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from sensor_msgs.msg import Illuminance, JointState

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
from tskf_ros.owc.vibrating_link import OwcLinkConfig, simulate_link
from tskf_ros.tools.demo_collector import wait_for

# s: a bound on waiting for DDS (discovery, matching, delivery), never an assertion about
# timing; generous for a loaded 2-core machine, it costs nothing when things work
TIMEOUT = 60.0


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


@pytest.mark.parametrize('publish_invalid', [False, True])
def test_simulator_publishes_the_seeded_stream_with_gaps(ros_context, executor_kind,
                                                         publish_invalid):
    params = {'seed': 3, 'duration': 120.0, 'time_factor': 200.0, 'start_time': 1.0,
              'knob_max': 1.5, 'knob_initial': 1.0, 'blockage': 'bernoulli',
              'drop_probability': 0.1, 'publish_invalid': publish_invalid,
              'wait_for_subscribers': 1}
    # the reference: the ROS-free link with the same settings
    cfg = OwcLinkConfig(**{k: v for k, v in params.items()
                           if k in OwcLinkConfig.__dataclass_fields__})
    s = simulate_link(cfg, 120)
    shown = ~s.blocked & (s.valid | publish_invalid)
    sim = PowerMeterSimulator(context=ros_context, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    client = rclpy.create_node('client', context=ros_context)
    power, truth = [], []
    # in process (delivered in the publish call) into queues deeper than the whole stream:
    # the test controls the transport, so the best-effort power topic loses nothing here
    client.create_subscription(Illuminance, 'received_power', power.append,
                               QoSProfile(depth=1000, reliability=qos_profile_sensor_data
                                          .reliability))
    client.create_subscription(JointState, 'true_angle', truth.append, QoSProfile(depth=1000))
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(sim)
    executor.add_node(client)
    try:
        # every message the link shows, taken: no flush needed after this
        spin_until(executor, lambda: sim.published == 120 and len(truth) == 120
                   and len(power) == int(shown.sum()),
                   lambda: f'the stream ({sim.published} of 120 samples published, '
                   f'{len(truth)} true angles and {len(power)} of {int(shown.sum())} powers '
                   'received)')
    finally:
        executor.shutdown()
        sim.destroy_node()
        client.destroy_node()
    stamps = NS + np.arange(120) * NS
    np.testing.assert_array_equal([conversions.msg_to_angle(m)[0] for m in truth], stamps)
    # the values cross a float64 message unchanged; the tolerance only states that
    np.testing.assert_allclose([conversions.msg_to_angle(m)[1][0] for m in truth], s.theta,
                               rtol=0, atol=1e-12)
    got = [conversions.msg_to_power(m) for m in power]
    np.testing.assert_array_equal([g[0] for g in got], stamps[shown])
    np.testing.assert_allclose([g[1] for g in got], s.reading[shown], rtol=0, atol=1e-12)
    assert all(g[2] == 100.0 for g in got)
    # the stream has both kinds of gaps, and invalid readings appear only when asked for
    assert np.any(~s.valid & ~s.blocked) and np.any(s.blocked)
    assert any(g[1] <= 0 for g in got) == publish_invalid


def test_simulator_at_1khz(ros_context, executor_kind):
    sim = PowerMeterSimulator(context=ros_context, parameter_overrides=[
        Parameter('rate', value=1000.0), Parameter('duration', value=0.3),
        Parameter('start_time', value=1.0)])
    executor = make_executor(executor_kind, context=ros_context)
    executor.add_node(sim)
    try:
        spin_until(executor, lambda: sim.published == 300, '300 samples')
    finally:
        executor.shutdown()
        sim.destroy_node()
    assert sim.link.count == 300
