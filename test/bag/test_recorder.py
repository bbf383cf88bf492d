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

"""The recorder: raw bags rosbags and mcap read, no losses, signals, a full disk, SIGKILL."""

import os
import signal
import subprocess
import sys
import threading
import time

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSProfile,
                       ReliabilityPolicy)
from rclpy.serialization import deserialize_message
from recording import latched_source, stop, wait_until_recording
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import Illuminance, JointState

from tskf_ros.bag import reindex
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.recorder import Recorder
from tskf_ros.bag.writer import BagExistsError
from tskf_ros.messages import conversions
from tskf_ros.tools.demo_collector import wait_for

import yaml

from .helpers import NS, T0, TIMEOUT
from .test_writer import read_all

WINDOW = 2000


def spin_until(executor, condition, what):
    """Spin until condition(); fail, saying what never happened, after TIMEOUT."""
    wait_for(executor, condition, what, TIMEOUT)


def test_recorder_writes_a_bag_rosbags_and_mcap_read(ros_context, tmp_path):
    pub_node = rclpy.create_node('source', context=ros_context)
    power = pub_node.create_publisher(Illuminance, 'received_power', qos_profile_sensor_data)
    angle = pub_node.create_publisher(JointState, 'true_angle',
                                      QoSProfile(depth=100,
                                                 reliability=ReliabilityPolicy.RELIABLE))
    bag = tmp_path / 'rec'
    rec = Recorder(bag, topics=['/received_power', '/true_angle'], context=ros_context)
    # one process: the best-effort power reaches the recorder's keep-all queue within the
    # publish call, so the test controls the transport and may count every message
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(rec)
    executor.add_node(pub_node)
    try:
        spin_until(executor, lambda: len(rec.counts) == 2, 'subscriptions')
        spin_until(executor, lambda: power.get_subscription_count() == 1
                   and angle.get_subscription_count() == 1, 'matching')
        for k in range(50):
            stamp = T0 + k * NS
            power.publish(conversions.power_to_msg(stamp, 100.0 + k, 4.0))
            angle.publish(conversions.angle_to_msg(stamp, [0.5 + k / 1000], ['theta']))
            executor.spin_once(timeout_sec=0.001)
        spin_until(executor, lambda: rec.counts == {'/received_power': 50, '/true_angle': 50},
                   'all 100 messages')
        assert not bag.exists(), 'the bag appears under its name only when closed'
        assert rec.close() == bag
    finally:
        executor.shutdown()
        rec.destroy_node()
        pub_node.destroy_node()
    # rosbags: metadata (topics, types, counts, QoS, start, duration)
    with Reader(bag) as reader:
        assert reader.message_count == 100
        topics = reader.topics
        assert topics['/received_power'].msgtype == 'sensor_msgs/msg/Illuminance'
        assert topics['/received_power'].msgcount == 50
        assert topics['/true_angle'].msgtype == 'sensor_msgs/msg/JointState'
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert qos['/received_power'][0].reliability.name == 'BEST_EFFORT'
        assert qos['/true_angle'][0].reliability.name == 'RELIABLE'
        times = [t for _, t, _ in reader.messages()]
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['storage_identifier'] == 'mcap'
    assert meta['message_count'] == 100
    assert meta['starting_time']['nanoseconds_since_epoch'] == min(times)
    # rosbags writes max - min + 1 (the end is exclusive)
    assert meta['duration']['nanoseconds'] in (max(times) - min(times),
                                               max(times) - min(times) + 1)
    with AnyReader([bag]) as reader:
        values = [reader.deserialize(raw, c.msgtype).illuminance
                  for c, _, raw in reader.messages() if c.topic == '/received_power']
    assert values == [100.0 + k for k in range(50)]
    # mcap + mcap_ros2's decoder
    with (bag / 'rec.mcap').open('rb') as f:
        decoded = [(ch.topic, m) for _, ch, _, m in
                   make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    stamps = [conversions.stamp_to_ns(m.header.stamp) for t, m in decoded
              if t == '/received_power']
    assert stamps == [T0 + k * NS for k in range(50)]


@pytest.mark.slow
def test_recorder_loses_nothing_at_1khz_for_a_minute_of_stamps(ros_context, tmp_path):
    """
    Record 60 000 messages stamped 1 ms apart, published as fast as the publisher can.

    Not in real time (a minute is too long for the suite): the publisher thread runs as
    fast as the recorder takes them (about 5x 1 kHz here), so the rate is exceeded.
    """
    n = 60_000
    pub_node = rclpy.create_node('fast_source', context=ros_context)
    # reliable, with a history that holds the whole run: the writer never blocks or drops,
    # so a message missing from the bag would be the recorder's loss
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=n,
                     reliability=ReliabilityPolicy.RELIABLE)
    pub = pub_node.create_publisher(Illuminance, 'fast_power', qos)
    bag = tmp_path / 'fast'
    rec = Recorder(bag, topics=['/fast_power'], context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(rec)
    # the recorder's count advances in this thread; the publisher waits on it, woken up
    # after every spin (no polling sleep), and gives up when told to stop
    progress = threading.Condition()
    stop = threading.Event()
    failure = []

    def recorded():
        return rec.counts.get('/fast_power', 0)

    def publish(msgs):
        # stay at most WINDOW messages ahead of the recorder (application-level flow
        # control: Python's GIL would otherwise starve the recorder's executor); a lost
        # message would stall the window and fail the test
        try:
            for k, m in enumerate(msgs):
                with progress:
                    if not progress.wait_for(
                            lambda: stop.is_set() or k - recorded() <= WINDOW, TIMEOUT):
                        failure.append(f'the recorder took nothing for {TIMEOUT:g} s')
                        return
                if stop.is_set():
                    return
                pub.publish(m)
        except Exception as exc:        # reported by the test, not lost in the thread
            failure.append(repr(exc))

    # daemon, and joined with a timeout: a stuck publisher fails the test, never hangs it
    thread = None
    try:
        spin_until(executor, lambda: '/fast_power' in rec.counts, 'the recorder subscribing')
        spin_until(executor, lambda: pub.get_subscription_count() == 1, 'matching')
        msgs = [conversions.power_to_msg(T0 + k * 1_000_000, 1.0 + k, 0.0) for k in range(n)]
        thread = threading.Thread(target=publish, args=(msgs,), daemon=True)
        t0 = time.monotonic()
        thread.start()
        # a bound on progress, not on the whole run (its length depends on the machine):
        # fail when the count has not moved for TIMEOUT s
        last, last_change = 0, time.monotonic()
        while recorded() < n:
            assert not failure, failure[0]
            executor.spin_once(timeout_sec=0.01)
            with progress:
                progress.notify_all()
            if recorded() != last:
                last, last_change = recorded(), time.monotonic()
            assert time.monotonic() - last_change < TIMEOUT, \
                f'the recorder stalled at {last} of {n} messages ' \
                f'(write error: {getattr(rec, "failed", None)})'
        elapsed = time.monotonic() - t0
        thread.join(timeout=TIMEOUT)
        assert not thread.is_alive(), 'the publisher thread did not finish'
        assert not failure, failure[0]
        rec.close()
    finally:
        stop.set()
        with progress:
            progress.notify_all()
        if thread is not None:
            thread.join(timeout=TIMEOUT)
        executor.shutdown()
        rec.destroy_node()
        pub_node.destroy_node()
    print(f'recorded {n} messages in {elapsed:.1f} s ({n / elapsed:,.0f} msgs/s)')
    reader = BagReader(bag)
    assert reader.topics['/fast_power'].count == n
    got = [conversions.stamp_to_ns(m.header.stamp) for m in
           (deserialize_message(r.data, Illuminance)
            for r in reader.messages())]
    assert got == [T0 + k * 1_000_000 for k in range(n)]


def test_recorder_refuses_to_overwrite(ros_context, tmp_path):
    bag = tmp_path / 'exists'
    bag.mkdir()
    with pytest.raises(BagExistsError, match='exists already'):
        Recorder(bag, topics=['/x'], context=ros_context)
    rec = Recorder(bag, topics=['/x'], overwrite=True, context=ros_context)
    rec.destroy_node()
    assert (bag / 'metadata.yaml').is_file()


@pytest.mark.slow
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_record_command_closes_the_bag_on_a_signal(tmp_path, sig):
    # A reliable, transient-local publisher: the recorder takes its QoS from the graph, so
    # every message reaches it whenever it matches, and wait_for_all_acked says when all
    # 20 are in its reader; on the signal the recorder drains them before closing.
    bag = tmp_path / 'sig'
    context, node, pub = latched_source('sig_source', 'sig_power', [1.0] * 20)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.recorder', '-o', str(bag), '--topics', '/sig_power'],
        env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_until_recording(pub, proc, TIMEOUT, pub.topic_name)
        assert pub.wait_for_all_acked(Duration(seconds=TIMEOUT)), \
            'the recorder never acknowledged the 20 messages'
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        stop(proc, node, context)
    assert proc.returncode == 0, err
    assert 'wrote' in err
    with Reader(bag) as reader:
        assert reader.message_count == 20, err


# -- faults: a full disk, SIGKILL ---------------------------------------------------------

FULL = 'No space left on device'


def power(k):
    """Return the power of sample k in mW: 200 + k, exact in binary."""
    return 200.0 + k


def powers(bag):
    """Return the powers recorded in a bag, in order (and check every reader agrees)."""
    read_all(bag)
    return [deserialize_message(m.data, Illuminance).illuminance
            for m in BagReader(bag).messages()]


def test_record_command_says_the_disk_filled_and_keeps_the_bag(tmp_path):
    bag = tmp_path / 'rec'
    code = (
        'import errno, os, sys\n'
        'from tskf_ros.bag import mcap_file\n'
        'real = mcap_file.OutputFile.write_some\n'
        'def write_some(self, view):\n'
        '    if self.pos + len(view) > 20000:\n'
        '        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))\n'
        '    return real(self, view)\n'
        'mcap_file.OutputFile.write_some = write_some\n'
        'from tskf_ros.bag.recorder import main\n'
        f"sys.exit(main(['record', '-o', {str(bag)!r}, '/full_power', "
        "'--flush-interval', '0.05']))\n")
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('full_source', context=context)
    pub = node.create_publisher(Illuminance, 'full_power', QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    proc = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        wait_until_recording(pub, proc, TIMEOUT, pub.topic_name)
        deadline = time.monotonic() + TIMEOUT
        k = 0
        while proc.poll() is None:      # publish until the recorder gives up
            assert time.monotonic() < deadline, 'the recorder never stopped'
            pub.publish(conversions.power_to_msg(T0 + k * NS, power(k), 4.0))
            k += 1
            time.sleep(0.002)           # pacing, not synchronisation
        _, err = proc.communicate(timeout=TIMEOUT)
    finally:
        stop(proc, node, context)
    assert proc.returncode == 1, err
    assert 'Traceback' not in err
    lines = [line for line in err.splitlines() if line.startswith('record: ')]
    assert len(lines) == 1, err
    assert lines[0].startswith(f'record: error: {bag}: the disk is full ({FULL}) after '), err
    kept = powers(bag)
    assert kept
    assert f'kept the {len(kept)} messages written before, closed in {bag} ' in lines[0]
    # what is kept is a run of what was published, in order, nothing skipped
    assert kept == [kept[0] + i for i in range(len(kept))]


def test_sigkill_loses_at_most_the_flush_interval(tmp_path, capsys):
    bag = tmp_path / 'killed'
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('kill_source', context=context)
    pub = node.create_publisher(Illuminance, 'kill_power', QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.recorder', '-o', str(bag), '/kill_power',
         '--flush-interval', '0.2'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    on_disk = 0
    try:
        wait_until_recording(pub, proc, TIMEOUT, pub.topic_name)
        deadline = time.monotonic() + TIMEOUT
        k = 0
        while on_disk < 30:             # until flushes have put 30 messages on disk
            assert time.monotonic() < deadline, 'nothing reached the disk'
            pub.publish(conversions.power_to_msg(T0 + k * NS, power(k), 4.0))
            k += 1
            time.sleep(0.01)            # pacing, not synchronisation
            files = list(tmp_path.glob('.killed.partial-*/killed/killed.mcap'))
            if k % 10 == 0 and files and files[0].stat().st_size:
                on_disk = sum(1 for _ in BagReader(files[0]).messages())
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=TIMEOUT)
    finally:
        stop(proc, node, context)
    assert not bag.exists()
    partials = list(tmp_path.glob('.killed.partial-*'))
    assert len(partials) == 1
    assert reindex.main([str(partials[0])]) == 0
    kept = powers(bag)
    assert len(kept) >= on_disk
    assert kept == [kept[0] + i for i in range(len(kept))]
