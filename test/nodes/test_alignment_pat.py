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

"""The alignment node's pointing supervisor in-process, against the LED link simulator node."""

from diagnostic_msgs.msg import DiagnosticArray
from node_helpers import call
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import SetBool, Trigger

from tskf_ros import led
from tskf_ros.core.diagnostic_status import ERROR, OK
from tskf_ros.experiments.alignment_pat import ACQUIRED_WITHIN
from tskf_ros.messages import conversions
from tskf_ros.messages.alignment_interface import (COMMAND_TOPIC, pat_state_qos,
                                                   PAT_STATE_TOPIC)
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.led_link_simulator import LedLinkSimulator
from tskf_ros.nodes.node_runner import make_executor
from tskf_ros.tools.demo_collector import wait_for

# s: only a bound on waiting for DDS and the loop (a loaded machine); every assertion is
# on the sample stamps (simulated time), none on the wall clock
TIMEOUT = 120.0
DT = 0.05
START = 1.0           # s: the stamp of sample 0
PHI0 = 60.0           # deg: the light starts 60 deg off the receiver (a cold start)
# s of tracking before a test blocks the beam: a full lock window (1 s) and the window of
# the in-lock mean intensity (20 samples) after it, so that the mean is of light
LOCK_TIME = 2.0
BLOCKED = 3.0         # s the beam stays blocked


class Loop:
    """
    The simulator and the alignment node (defaults: pat.enabled) on one executor.

    The simulator is built only once the client holds the node's latched start state: its
    sample 0 waits for the aligner's subscription alone, and a pat_state subscription
    matched after it (DDS matches endpoints asynchronously) would miss 'acquiring' if the
    cold start's hand-over came first (only the newest state is kept for a late one).
    """

    def __init__(self, context, executor_kind, *, command_timeout=TIMEOUT, **sim):
        self.node = Alignment(context=context, parameter_overrides=[
            Parameter('diagnostic_updater.period', value=3600.0),
            Parameter('status_period', value=0.0)])
        self.client = rclpy.create_node('pat_client', context=context)
        self.states, self.truth, self.commands, self.diagnostics = [], [], [], []
        deep = QoSProfile(depth=10000)
        # pat_state's durability and reliability, a history deep enough for every state
        latched = pat_state_qos()
        latched.depth = 10000
        self.client.create_subscription(String, PAT_STATE_TOPIC,
                                        lambda m: self.states.append(m.data), latched)
        self.client.create_subscription(JointState, 'true_angle', self.truth.append, deep)
        self.client.create_subscription(Float64MultiArray, COMMAND_TOPIC,
                                        self.commands.append, deep)
        self.client.create_subscription(DiagnosticArray, '/diagnostics',
                                        self.diagnostics.append, 10)
        self.executor = make_executor(executor_kind, context=context)
        for n in (self.node, self.client):
            self.executor.add_node(n)
        wait_for(self.executor, lambda: self.states == ['acquiring'],
                 lambda: f'the latched start state (got {self.states})', TIMEOUT)
        self.sim = LedLinkSimulator(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in dict(
                time_factor=0.0, start_time=START, wait_for_subscribers=1, phi0=PHI0,
                seed=11, command_timeout=command_timeout, status_period=0.0, **sim).items()])
        self.executor.add_node(self.sim)

    def spin_until(self, condition, what):
        """Spin until condition() holds (the loop runs meanwhile); fail after TIMEOUT."""
        wait_for(self.executor, condition, lambda: f'{what} (state '
                 f'{self.node.session.pat_state}, {self.sim.taken} samples)', TIMEOUT)

    def stamp(self):
        """Give the last sample's stamp in s."""
        return self.node.session.stats.last_stamp_ns / 1e9

    def until_state(self, state):
        """Run the loop until the supervisor is in state; return the stamp (s) it began at."""
        self.spin_until(lambda: self.node.session.pat_state == state
                        and self.states[-1:] == [state], state)
        return self.node.session.pointing.since_ns / 1e9

    def run_for(self, seconds):
        """Run the loop for `seconds` of sample stamps."""
        end = self.sim.taken + int(round(seconds / DT))
        self.spin_until(lambda: self.sim.taken >= end, f'{seconds} s of samples')

    def block(self, blocked):
        """Block (or clear) the simulator's beam at run time, as `ros2 param set` does."""
        result = self.sim.set_parameters([Parameter('beam_blocked', value=blocked)])[0]
        assert result.successful, result.reason

    def service(self, srv_type, name, request):
        """Call one of the node's services; return the response."""
        client = self.client.create_client(srv_type, f'/alignment/{name}')
        return call(self.executor, client, request)

    def pointing(self):
        """
        Publish the diagnostics now; return the 'pointing' task's level and values.

        The node's own message is taken (the simulator publishes on /diagnostics too);
        every task of it is kept in self.tasks.
        """
        n = len(self.diagnostics)
        self.node.publish_diagnostics()

        def own():
            return [d for d in map(conversions.msg_to_diagnostics, self.diagnostics[n:])
                    if 'alignment: pointing' in d]
        self.spin_until(lambda: bool(own()), "the aligner's /diagnostics")
        self.tasks = own()[-1]
        status = self.tasks['alignment: pointing']
        return status['level'], status

    def phi(self):
        """Return the true angle of incidence (deg) of every sample so far."""
        return np.array([conversions.msg_to_led_truth(m)[1]['incidence'] for m in self.truth])

    def close(self):
        """Take the nodes off the executor, shut it down, destroy them."""
        for n in (self.sim, self.node, self.client):
            self.executor.remove_node(n)
        self.executor.shutdown()
        for n in (self.sim, self.node, self.client):
            n.destroy_node()


@pytest.fixture
def make(ros_context, executor_kind):
    """Build a Loop in this test's context, on each executor; close it afterwards."""
    made = []

    def factory(**sim):
        loop = Loop(ros_context, executor_kind, **sim)
        made.append(loop)
        return loop
    yield factory
    for loop in made:
        loop.close()


def test_cold_start_acquires_and_tracks(make):
    loop = make()
    found = loop.until_state('tracking')
    # seen from the start: the latched state, then the hand-over
    assert loop.states == ['acquiring', 'tracking']
    assert loop.node.session.pointing.acquisitions == 1
    # the sweep reaches +90 first and then finds the light near -60 deg: a few seconds
    print(f'cold start: tracking {found - START:.2f} s (simulated) after sample 0')
    assert found - START <= ACQUIRED_WITHIN
    loop.run_for(LOCK_TIME)
    assert loop.node.session.pat_state == 'tracking'
    # in lock: within the tracking zone for the last second (the scan swings +-10 deg)
    phi = loop.phi()
    assert np.abs(phi[-int(LOCK_TIME / DT):]).max() <= led.TRACKING_ANGLE
    assert np.abs(phi[0]) == pytest.approx(PHI0, abs=0.5)
    level, values = loop.pointing()
    assert level == OK and values['State'] == 'tracking'
    assert values['Acquisitions'] == '1' and values['Losses'] == '0'


def test_blocked_beam_is_lost_and_reacquired(make):
    loop = make()
    loop.until_state('tracking')
    loop.run_for(LOCK_TIME)
    assert loop.node.session.pat_state == 'tracking'
    loop.block(True)
    first_dark = loop.sim.taken          # the index of the next sample: the first dark one
    lost = loop.until_state('lost')
    # M = 12 of the N = 20 samples of the lock window dark: declared at the 12th to 20th
    dark = int(round((lost - START) / DT)) - first_dark + 1
    print(f'loss declared at the {dark}th dark sample')
    assert 12 <= dark <= 20
    level, values = loop.pointing()
    assert level == ERROR and values['State'] == 'lost'
    assert values['Losses'] == '1'
    assert float(values['Last loss (stamp, s)']) == pytest.approx(lost, abs=1e-6)
    loop.run_for(BLOCKED)
    assert loop.node.session.pat_state == 'lost'       # nothing to find in the dark
    loop.block(False)
    cleared = loop.stamp()
    found = loop.until_state('tracking')
    print(f're-acquired {found - cleared:.2f} s after the beam was cleared')
    assert found - cleared <= ACQUIRED_WITHIN
    assert loop.states == ['acquiring', 'tracking', 'lost', 'tracking']
    p = loop.node.session.pointing
    assert (p.losses, p.reacquisitions, p.acquisitions) == (1, 1, 1)


def test_acquire_forces_a_search_and_a_late_subscriber_gets_the_state(make):
    loop = make()
    loop.until_state('tracking')
    response = loop.service(Trigger, 'acquire', Trigger.Request())
    assert response.success and response.message == 'searching'
    assert loop.node.session.pointing.requests == 1
    # published at once (the next sample may already be searching with it)
    loop.spin_until(lambda: loop.states[-1:] == ['acquiring'], 'the acquiring state')
    late = []
    loop.client.create_subscription(String, PAT_STATE_TOPIC, lambda m: late.append(m.data),
                                    pat_state_qos())
    loop.until_state('tracking')
    loop.spin_until(lambda: late[-1:] == ['tracking'], 'the late subscriber')
    # latched: the late subscriber got the state then, not the history
    assert late[0] in ('acquiring', 'tracking') and len(late) <= 2
    assert loop.states == ['acquiring', 'tracking', 'acquiring', 'tracking']


def test_enable_false_pauses_the_supervisor_too(make):
    # no command answers a paused sample: the simulator goes on after 0.05 s (wall clock)
    loop = make(command_timeout=0.05)
    loop.until_state('tracking')
    assert loop.service(SetBool, 'enable', SetBool.Request(data=False)).message == 'paused'
    commands, stats = len(loop.commands), loop.node.session.stats
    loop.block(True)
    paused = stats.paused
    loop.spin_until(lambda: stats.paused >= paused + 30, '30 paused samples')
    # no step, no command, no loss declared in the dark while paused
    assert len(loop.commands) == commands
    assert loop.node.session.pat_state == 'tracking'
    level, values = loop.pointing()
    assert level == OK and 'paused' in values['message']
    assert loop.service(SetBool, 'enable', SetBool.Request(data=True)).message == 'enabled'
    loop.until_state('lost')
    assert loop.states == ['acquiring', 'tracking', 'lost']


def test_acquire_without_the_supervisor_says_so(ros_context):
    node = Alignment(context=ros_context,
                     parameter_overrides=[Parameter('pat.enabled', value=False)])
    try:
        response = node._on_acquire(Trigger.Request(), Trigger.Response())
        assert not response.success and 'pat.enabled is false' in response.message
        assert node.session.pat_state == 'disabled'
        # switched on at run time: the aligner restarts, searching
        assert node.set_parameters([Parameter('pat.enabled', value=True)])[0].successful
        assert node.session.pat_state == 'acquiring' and node.session.supervisor is not None
        assert node.session.stats.resets['reconfigured'] == 1
        result = node.set_parameters([Parameter('pat.scan_speed', value=50.0)])[0]
        assert not result.successful and 'exceeds max_step' in result.reason
    finally:
        node.destroy_node()


def test_repeated_acquire_while_searching_does_not_walk_the_search_away(make):
    # over DDS before: ten requests once a second moved the base to 360 deg and the
    # search stayed there, the light at -60 deg beyond its +-90 deg
    loop = make()
    requests = 0
    for _ in range(10):
        loop.run_for(1.0)
        if loop.node.session.pat_state != 'acquiring':
            break
        assert loop.service(Trigger, 'acquire', Trigger.Request()).success
        requests += 1
    sup = loop.node.session.supervisor
    assert requests >= 1 and sup.sweep.center[0] == 0.0      # where the cold search began
    assert abs(loop.node.session.base) <= 90.0 + 1e-9
    loop.until_state('tracking')


def test_a_gate_change_reaches_the_supervisors_nis_band_at_once(make):
    # before: 'new parameters in use', the band kept the old gate until ~/reset
    from tskf_ros.led.lock_detector import nis_band
    loop = make()
    loop.until_state('tracking')
    result = loop.node.set_parameters([Parameter('gate', value=2.0)])[0]
    assert result.successful, result.reason
    sup = loop.node.session.supervisor
    cfg = sup.config.lock
    assert cfg.gate == 2.0 and loop.node.session.pat_state == 'tracking'
    np.testing.assert_allclose(sup.lock.bands, [nis_band(k, cfg.nis_alpha, 2.0)
                                                for k in range(cfg.window + 1)], rtol=1e-12)
    _, values = loop.pointing()
    aligner = loop.tasks['alignment: aligner']
    assert aligner['Messages lost (transport)'] == '0'
    assert 'Samples missed (stamps)' in aligner
