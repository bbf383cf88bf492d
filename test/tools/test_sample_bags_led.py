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
bags/led_alignment is in the alignment node's units: radians (REP 103) and its command type.

The bag is read with the package's BagReader and decoded with rclpy (rosbags' strict CDR
reader refuses the JointState bytes rclpy serializes: they end in padding it does not
expect), and compared with an independent re-run of the simulation that made it
(tskf_ros.led.simulate_tracking, seed 2013, Table I, 5 % of the measurements missing), whose
angles are in degrees; the conversion to radians is done here with math.radians.  Floats
agree to a relative 1e-9 (numpy's SIMD paths differ between CPUs in the last bits), with an
absolute floor of 1e-12 for values near zero.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import deserialize_message

from tskf_ros import led
from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader

BAG = Path(__file__).resolve().parents[2] / 'bags' / 'led_alignment'
SEED = 2013                    # bags/README.md's command for led_alignment
DROPOUT = 0.05                 # 5 % of the measurements missing
STEP_NS = 50_000_000           # Table I: 50 ms
START_NS = 1_700_000_000 * 10**9
REL, ABS = 1e-9, 1e-12


class RecordingEKF(led.ScanningEKF):
    """The scanning EKF, keeping its posterior covariance (deg) after every step."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.covariances = []

    def step(self, stamp, z):
        cmd = super().step(stamp, z)
        self.covariances.append(np.array(self.P[0], dtype=float))
        return cmd


@pytest.fixture(scope='module')
def bag():
    """Return {topic: (type, [(log time ns, message)])} of the bag."""
    out = {}
    reader = BagReader(BAG)
    for m in reader.messages():
        entry = out.setdefault(m.topic, (m.msgtype, []))
        entry[1].append((m.log_time_ns, deserialize_message(m.data, message_class(m.msgtype))))
    assert reader.damage is None
    return out


@pytest.fixture(scope='module')
def simulation():
    """Re-run the simulation that made the bag: (trajectory in deg, covariances in deg)."""
    ekf = RecordingEKF(led.EKFConfig(), runs=1)
    traj = led.simulate_tracking(ekf, led.TrackingLinkConfig(dropout=DROPOUT),
                                 np.random.default_rng(SEED))
    return traj, ekf.covariances


def close(got, want):
    """Return whether got equals want to a relative REL (absolute ABS near zero)."""
    return got == pytest.approx(want, rel=REL, abs=ABS)


def test_topics_types_and_stamps(bag, simulation):
    traj, _ = simulation
    steps = len(traj.t)
    assert steps == 400
    assert {t: (kind, len(msgs)) for t, (kind, msgs) in bag.items()} == {
        '/photodiode': ('sensor_msgs/msg/Illuminance', int(np.isfinite(traj.z[:, 0]).sum())),
        '/alignment/truth': ('sensor_msgs/msg/JointState', steps),
        '/alignment/estimate': ('std_msgs/msg/Float64MultiArray', steps),
        '/alignment/command': ('std_msgs/msg/Float64MultiArray', steps),
    }
    for topic in ('/alignment/truth', '/alignment/estimate', '/alignment/command'):
        assert [ns for ns, _ in bag[topic][1]] == [START_NS + k * STEP_NS for k in range(steps)]


def test_truth_is_in_radians_with_unit_free_names(bag, simulation):
    traj, _ = simulation
    truth = bag['/alignment/truth'][1]
    for k, (log_ns, msg) in enumerate(truth):
        assert list(msg.name) == ['incidence', 'scan_mean', 'intensity_factor']
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == log_ns
        incidence, scan_mean, intensity = msg.position
        assert close(incidence, math.radians(traj.phi[k, 0])), k
        assert close(scan_mean, math.radians(traj.x2[k, 0])), k
        assert close(intensity, traj.x1[k, 0]), k       # volts, not converted
    incidence = np.array([m.position[0] for _, m in truth])
    # the scan swings about +-10 deg: about +-0.18 rad, far from the degree values
    assert 0.1 < np.abs(incidence).max() < 0.3


def test_command_is_the_absolute_base_position_in_radians(bag, simulation):
    traj, _ = simulation
    turns_deg = [float(c) for c in traj.command[:, 0]]
    for k, (_, msg) in enumerate(bag['/alignment/command'][1]):
        assert len(msg.data) == 1
        assert close(float(msg.data[0]), math.radians(math.fsum(turns_deg[:k + 1]))), k
    # absolute, not the turn of the step: it differs from the last turn once the base moved
    last = float(bag['/alignment/command'][1][-1][1].data[0])
    assert not close(last, math.radians(turns_deg[-1]))


def test_estimate_is_in_the_node_units(bag, simulation):
    traj, covariances = simulation
    r = math.pi / 180.0
    for k, (log_ns, msg) in enumerate(bag['/alignment/estimate'][1]):
        x1hat, x2hat_deg = traj.estimate[k, 0]
        # the estimate layout, read by hand: [sec, nanosec, mu, x1, x2, P row-major]
        assert msg.layout.data_offset == 3 and len(msg.data) == 3 + 2 + 4
        assert [d.label for d in msg.layout.dim] == ['corrected',
                                                     'x1_intensity_V,x2_scan_mean_rad']
        assert int(msg.data[0]) * 10**9 + int(msg.data[1]) == log_ns
        assert msg.data[2] == (0.0 if k == 0 else STEP_NS / 1e9), k
        assert close(msg.data[3], x1hat), k
        assert close(msg.data[4], math.radians(x2hat_deg)), k
        cov = np.asarray(msg.data[5:], dtype=float).reshape(2, 2)
        P = covariances[k]
        assert close(cov[0, 0], P[0, 0]), k
        assert close(cov[0, 1], P[0, 1] * r), k
        assert close(cov[1, 0], P[1, 0] * r), k
        assert close(cov[1, 1], P[1, 1] * r * r), k
