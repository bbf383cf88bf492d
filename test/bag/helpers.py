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

"""What the bag tests share: sample paths, small bags, one-line error checks, flattening."""

import array
import dataclasses
from pathlib import Path

import numpy as np
from rclpy.serialization import serialize_message
from sensor_msgs.msg import FluidPressure, Range, Temperature
from std_msgs.msg import Float64, String
from stderr_lines import error_lines, one_line, usage_error  # noqa: F401 - the bag tests' import

from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
REPO = Path(__file__).resolve().parent.parent.parent
BAGS = REPO / 'bags'
CONFIG = REPO / 'config'
SAMPLES = ('owc_cai_td_1hz', 'owc_ge_1khz', 'led_alignment', 'led_pan_tilt', 'drogue')
# s: a bound on waiting for a subprocess or DDS, never an assertion about timing
TIMEOUT = 60.0


def mcap_file(bag):
    """Return the (first) MCAP file of a bag directory."""
    return next(Path(bag).glob('*.mcap'))


def make_bag(path, times_s, *, start_ns=T0, chunk_size=None):
    """Write one Illuminance sample per log time (s after start_ns); return the path."""
    kwargs = {'chunk_size': chunk_size} if chunk_size else {}
    with BagWriter(path, **kwargs) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k, t in enumerate(times_s):
            stamp = start_ns + int(round(t * NS))
            w.write('/received_power', stamp, serialize_message(
                conversions.power_to_msg(stamp, 300.0 + k % 7, 4.0)))
    return path


def scalar_power(k):
    """Return a plausible received power in mW, exact in float32 (Range is float32)."""
    return float(np.float32(300.0 + 20.0 * np.sin(k / 7.0)))


def scalar_bag(path, n=60, msgtype='sensor_msgs/msg/Illuminance', topic='/received_power',
               filler=0, storage='mcap', compress=False):
    """Write n samples at 1 Hz (a gap at 20-22) and `filler` bytes of String per sample."""
    rng = np.random.default_rng(0)
    with BagWriter(path, storage=storage, compress=compress) as w:
        w.add_topic(topic, msgtype)
        if filler:
            w.add_topic('/filler', 'std_msgs/msg/String')
        for k in range(n):
            if 20 <= k < 23:
                continue
            stamp = T0 + k * NS
            if msgtype == 'sensor_msgs/msg/Illuminance':
                msg = conversions.power_to_msg(stamp, scalar_power(k), 100.0)
            elif msgtype == 'sensor_msgs/msg/Temperature':
                msg = Temperature(temperature=scalar_power(k), variance=1.0)
            elif msgtype == 'sensor_msgs/msg/FluidPressure':
                msg = FluidPressure(fluid_pressure=scalar_power(k), variance=1.0)
            elif msgtype == 'sensor_msgs/msg/Range':
                msg = Range(range=float(scalar_power(k)))
            elif msgtype == 'std_msgs/msg/Float64':
                msg = Float64(data=scalar_power(k))
            else:
                msg = String(data='not a number')
            if hasattr(msg, 'header'):
                msg.header.stamp = conversions.ns_to_stamp(stamp)
            w.write(topic, stamp, serialize_message(msg))
            if filler:
                text = rng.integers(0, 16, filler).astype(np.uint8)
                w.write('/filler', stamp, serialize_message(
                    String(data=''.join('0123456789abcdef'[i] for i in text))))
    return path


def chunk_offsets(mcap):
    """Return (offset, length) of the top-level Chunk records of an MCAP file (opcode 0x06)."""
    data = mcap.read_bytes()
    pos, out = 8, []
    while pos + 9 <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1:pos + 9], 'little')
        if op == 0x06:
            out.append((pos, length))
        if op == 0x0F:           # DataEnd
            break
        pos += 9 + length
    return out


def field_names(msg):
    """Return the field names of an rclpy, rosbags or mcap_ros2 message, or None."""
    if dataclasses.is_dataclass(msg):                       # rosbags
        return [f.name for f in dataclasses.fields(msg) if not f.name.startswith('__')]
    if hasattr(msg, 'get_fields_and_field_types'):         # rclpy
        return list(msg.get_fields_and_field_types())
    if hasattr(msg, '__slots__') and not isinstance(msg, (list, tuple, np.ndarray)):
        return list(msg.__slots__)                          # mcap_ros2's dynamic classes
    return None


def flatten(msg, prefix=''):
    """Return {field path: value} of a message, recursing into nested messages and lists."""
    names = field_names(msg)
    if names is not None:
        out = {}
        for name in names:
            out.update(flatten(getattr(msg, name), f'{prefix}.{name}'))
        return out
    if isinstance(msg, (list, tuple, array.array, np.ndarray)):
        out = {f'{prefix}.len': len(msg)}
        for i, item in enumerate(msg):
            out.update(flatten(item, f'{prefix}[{i}]'))
        return out
    if isinstance(msg, bytes) and len(msg) == 1:      # rclpy's `byte`; the others give an int
        return {prefix: msg[0]}
    if isinstance(msg, (float, np.floating)):
        return {prefix: float(msg)}
    return {prefix: msg.item() if isinstance(msg, np.generic) else msg}
