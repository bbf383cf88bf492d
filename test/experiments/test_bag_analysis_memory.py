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

"""The sweep's evaluation of a bag in bounded memory: peak RSS at 2e4 and 2e5 messages."""

import os
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from tskf_ros.bag.writer import BagWriter

NS = 1_000_000_000
EVALUATE = """
import sys
from tskf_ros.experiments.bag_analysis import evaluate_bag
from tskf_ros.messages.estimator_interface import load_config
row = evaluate_bag(sys.argv[1], load_config(sys.argv[2]))
print(row['n_messages'], row['steps'])
"""
# bytes a message may keep: none is kept (the innovations are in a temporary file);
# this bounds what the window of newest points swings by
PER_MESSAGE = 20


def write_bag(path: Path, n: int, seed: int) -> None:
    """Write n Illuminance messages at 1 kHz, stamps jittered +-10 us."""
    from rclpy.serialization import serialize_message
    from tskf_ros.messages import conversions
    rng = np.random.default_rng(seed)
    stamps = 1_700_000_000 * NS + np.arange(n) * 1_000_000 + rng.integers(-10_000, 10_001, n)
    values = 300.0 + rng.normal(0.0, 2.0, n)
    with BagWriter(path) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for t, v in zip(stamps.tolist(), values.tolist()):
            w.write('/received_power', t + 200_000,
                    serialize_message(conversions.power_to_msg(t, v, 4.0)))


def peak_rss_mb(bag: Path, params: Path) -> tuple[float, str]:
    """Evaluate the bag in a process of its own; return its peak RSS (MB) and its output."""
    proc = subprocess.Popen([sys.executable, '-c', EVALUATE, str(bag), str(params)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, OPENBLAS_NUM_THREADS='1'))
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, out
    return usage.ru_maxrss / 1024, out.strip().splitlines()[-1]


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_the_bag(tmp_path):
    # once every message cost about 2.6 KB (470 MB more at 2e5 than at 2e4 messages),
    # then the NIS terms, 32 bytes; now nothing: at most PER_MESSAGE bytes a message
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    period: 0.001\n')
    peaks = {}
    for n in (20_000, 200_000):
        write_bag(tmp_path / f'bag_{n}', n, seed=n)
        peaks[n], out = peak_rss_mb(tmp_path / f'bag_{n}', params)
        assert out.split()[0] == str(n)
    growth = peaks[200_000] - peaks[20_000]
    assert growth < 180_000 * PER_MESSAGE / 2**20 + 8.0, peaks
