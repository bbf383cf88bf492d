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
bags/led_pan_tilt is the two-axis loop in the alignment node's units, against a re-run.

The bag is read with the package's BagReader and decoded with rosbags (strict CDR) and
mcap_ros2 (every message of the bag, test/bag/test_cdr.py, decodes alike with rclpy too);
it is compared with an independent re-run of the ROS-free loop that made it
(tskf_ros.led.two_axis.pan_tilt_closed_loop, seed 2013, 5 % of the samples missing), whose
angles are in degrees; the conversion to radians is done here with math.radians.  Floats
agree to a relative 1e-9 (numpy's SIMD paths differ between CPUs in the last bits), with an
absolute floor of 1e-12 for values near zero.
"""

import math
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest

from tskf_ros.bag.message_types import typestore
from tskf_ros.bag.reader import BagReader
from tskf_ros.led.two_axis.pan_tilt_link import PanTiltLinkConfig
from tskf_ros.led.two_axis.pan_tilt_session import (pan_tilt_closed_loop, PanTiltSession,
                                                    PanTiltSessionConfig)

BAG = Path(__file__).resolve().parents[2] / 'bags' / 'led_pan_tilt'
SEED = 2013                    # bags/README.md's command for led_pan_tilt
STEPS = 400
START_NS = 1_700_000_000 * 10**9
REL, ABS = 1e-9, 1e-12
NAMES = ['pan', 'tilt', 'source_azimuth', 'source_elevation', 'off_axis']


@pytest.fixture(scope='module')
def bag():
    """Return {topic: [(log time ns, message decoded by rosbags)]} of the bag."""
    store = typestore()
    out: dict = {}
    reader = BagReader(BAG)
    for m in reader.messages():
        out.setdefault(m.topic, []).append((m.log_time_ns,
                                            store.deserialize_cdr(m.data, m.msgtype)))
    assert reader.damage is None
    return out


@pytest.fixture(scope='module')
def run():
    """Re-run the loop that made the bag."""
    link = PanTiltLinkConfig(dropout=0.05)
    return pan_tilt_closed_loop(link, PanTiltSession(PanTiltSessionConfig(noise=link.noise)),
                                STEPS, seed=SEED, start_ns=START_NS)


def close(got, want):
    """Return whether got equals want to a relative REL (absolute ABS near zero)."""
    return got == pytest.approx(want, rel=REL, abs=ABS)


def test_topics_counts_and_stamps(bag, run):
    delivered = [o for o in run.outcomes if o is not None]
    assert 0 < STEPS - len(delivered) < 0.1 * STEPS      # some dropped
    assert {t: len(msgs) for t, msgs in bag.items()} == {
        '/photodiode': len(delivered), '/pan_tilt/truth': STEPS,
        '/pan_tilt/estimate': len(delivered), '/pan_tilt/command': len(delivered)}
    assert [ns for ns, _ in bag['/pan_tilt/truth']] == [
        START_NS + int(round(s.t * 1e9)) for s in run.samples]
    assert [ns for ns, _ in bag['/pan_tilt/command']] == [o.stamp_ns for o in delivered]


def test_truth_is_in_radians(bag, run):
    for (log_ns, msg), s in zip(bag['/pan_tilt/truth'], run.samples):
        assert list(msg.name) == NAMES
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == log_ns
        want = [*s.joints[0], *s.source[0], s.theta[0]]
        assert all(close(g, math.radians(w)) for g, w in zip(msg.position, want))
    theta = np.array([m.position[4] for _, m in bag['/pan_tilt/truth']])
    assert theta[0] == pytest.approx(math.radians(5.0), rel=1e-12)    # offset0
    assert theta[40:].max() < math.radians(15.0)                      # tracked


def test_commands_and_estimates_are_the_sessions_in_radians(bag, run):
    delivered = [o for o in run.outcomes if o is not None]
    r = math.pi / 180.0
    stamps = [o.stamp_ns for o in delivered]
    for k, ((_, cmd), (_, est), o) in enumerate(zip(bag['/pan_tilt/command'],
                                                    bag['/pan_tilt/estimate'], delivered)):
        assert cmd.layout.dim[0].label == 'pan,tilt' and len(cmd.data) == 2
        assert close(cmd.data[0], math.radians(o.command[0])), k
        assert close(cmd.data[1], math.radians(o.command[1])), k
        n = len(o.estimate.x)
        assert est.layout.data_offset == 3 and len(est.data) == 3 + n + n * n
        assert est.layout.dim[0].label == 'corrected'
        assert est.layout.dim[1].label.split(',')[:3] == [
            'x1_intensity_V', 'd_cross_elevation_rad', 'd_elevation_rad']
        assert int(est.data[0]) * 10**9 + int(est.data[1]) == o.stamp_ns
        mu = 0.0 if k == 0 else (stamps[k] - stamps[k - 1]) / 1e9
        assert est.data[2] == pytest.approx(mu, abs=1e-12)
        scale = np.array([1.0] + [r] * (n - 1))
        assert all(close(g, w) for g, w in zip(est.data[3:3 + n], o.estimate.x * scale))
        P = np.asarray(est.data[3 + n:]).reshape(n, n)
        want = o.estimate.P * np.outer(scale, scale)
        assert all(close(g, w) for g, w in zip(P.ravel(), want.ravel())), k


def test_mcap_ros2_decodes_the_same_values(bag):
    (path,) = BAG.glob('*.mcap')
    with path.open('rb') as f:
        decoded = [(ch.topic, m.log_time, d) for _, ch, m, d in
                   make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    by_topic: dict = {}
    for topic, log_ns, msg in decoded:
        by_topic.setdefault(topic, []).append((log_ns, msg))
    for (ns, a), (ns2, b) in zip(bag['/pan_tilt/command'], by_topic['/pan_tilt/command']):
        assert ns == ns2 and list(a.data) == list(b.data)
    for (_, a), (_, b) in zip(bag['/pan_tilt/truth'], by_topic['/pan_tilt/truth']):
        assert list(a.name) == list(b.name) and list(a.position) == list(b.position)
