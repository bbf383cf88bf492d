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
"""replay_offline's outputs under Ctrl-C and SIGKILL: never a hang, never a partial left."""

import os
import signal
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from tskf_ros.bag.partials import remove_stale
from tskf_ros.bag.replay.loop import replay_arrays
from tskf_ros.bag.replay.npz_output import replay_npz
from tskf_ros.bag.writer import BagWriter

from ..helpers import NS, REPO, T0, TIMEOUT

PARAMS = '/**:\n  ros__parameters:\n    period: 0.001\n'


def illuminance(stamp_ns, value):
    """Return the CDR of an Illuminance (frame 'pm'), as rclpy serializes it."""
    sec, nsec = divmod(stamp_ns, NS)
    head = struct.pack('<4siII', b'\0\1\0\0', sec, nsec, 3) + b'pm\0'
    return head + b'\0' * (-(len(head) - 4) % 8) + struct.pack('<dd', value, 4.0)


def long_bag(path, n, start_ns=T0):
    """Write n Illuminance samples at 1 kHz, stamps jittered +-10 us; return the path."""
    rng = np.random.default_rng(3)
    stamps = start_ns + np.arange(n) * 1_000_000 + rng.integers(-10_000, 10_001, n)
    with BagWriter(path) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k, t in enumerate(stamps.tolist()):
            w.write('/received_power', t + 100_000, illuminance(t, 300.0 + k % 7))
    return path


@pytest.fixture(scope='module')
def big(tmp_path_factory):
    """Return a bag long enough that replaying it takes seconds, and its params file."""
    folder = tmp_path_factory.mktemp('big')
    (folder / 'params.yaml').write_text(PARAMS)
    return long_bag(folder / 'bag', 150_000), folder / 'params.yaml'


def hidden(folder):
    """Return the hidden entries (work directories) in folder."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith('.'))


def start(bag, params, out, mode):
    """Start replay_offline into `out` (a bag, or --npz) in its own process."""
    target = ['--npz', str(out)] if mode == 'npz' else [str(out)]
    return subprocess.Popen(
        [sys.executable, '-c', 'from tskf_ros.tools.console import replay_offline; '
         'replay_offline()', str(bag), *target, '--params-file', str(params), '-q'],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_work_dir(proc, folder):
    """Wait (polling, with a deadline) until the replay has made its work directory."""
    deadline = time.monotonic() + TIMEOUT
    while not hidden(folder):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, 'no work directory appeared'
        time.sleep(0.01)        # polling a condition, with a deadline


@pytest.mark.parametrize('mode', ['npz', 'bag'])
@pytest.mark.parametrize('written', [0, 1 << 20])
def test_ctrl_c_while_writing_ends_with_nothing_left(big, tmp_path, mode, written):
    """SIGINT once the output's work directory exists (and once it holds 1 MiB): exit 130."""
    out = tmp_path / ('a.npz' if mode == 'npz' else 'out')
    proc = start(*big, out, mode)
    wait_for_work_dir(proc, tmp_path)
    deadline = time.monotonic() + TIMEOUT
    while sum(p.stat().st_size for p in tmp_path.rglob('*') if p.is_file()) < written:
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.01)        # polling a condition, with a deadline
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=TIMEOUT)      # a hang fails here
    assert proc.returncode == 130, err
    assert err.count('\n') <= 1 and 'Traceback' not in err
    assert list(tmp_path.iterdir()) == []           # no output, no work directory


@pytest.mark.parametrize('mode', ['npz', 'bag'])
def test_a_killed_run_leaves_a_work_directory_that_the_next_run_deletes(big, tmp_path, mode):
    out = tmp_path / ('a.npz' if mode == 'npz' else 'out')
    proc = start(*big, out, mode)
    wait_for_work_dir(proc, tmp_path)
    proc.kill()
    proc.communicate(timeout=TIMEOUT)
    left = hidden(tmp_path)
    assert len(left) == 1 and left[0].startswith(f'.{out.name}.partial-pid{proc.pid}-')
    # a work directory of a live process (this one), and the recorder's, are kept
    mine = tmp_path / f'.{out.name}.partial-pid{os.getpid()}-x'
    recorder = tmp_path / f'.{out.name}.partial-k3j9x1'
    mine.mkdir()
    recorder.mkdir()
    lines = []
    assert remove_stale(out, lines.append) == [tmp_path / left[0]]
    assert len(lines) == 1 and f'process {proc.pid} is gone' in lines[0]
    assert hidden(tmp_path) == sorted([mine.name, recorder.name])


def test_the_npz_holds_what_replay_arrays_returns(big, tmp_path):
    bag, params = big
    res = replay_npz(bag, tmp_path / 'a.npz', params)
    arrays = replay_arrays(bag, params)
    with np.load(tmp_path / 'a.npz') as f:
        assert sorted(f.keys()) == sorted(arrays)
        for key, value in arrays.items():
            assert f[key].dtype == value.dtype, key
            np.testing.assert_array_equal(f[key], value)        # the same rows, exact
    assert res.samples == len(arrays['sample.log_ns']) == 150_000
    assert hidden(tmp_path) == []
