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

"""The player's keys: read from a terminal only, typed in a real one (a pty)."""

import io
import os
import select
import signal
import subprocess
import sys
import termios
import time

import pytest

from tskf_ros.bag import keyboard

from .helpers import TIMEOUT
from .test_player import make_bag


def test_keys_are_read_only_from_a_terminal(monkeypatch):
    def no_tty(*args):
        raise AssertionError('termios used on a stream that is not a terminal')
    monkeypatch.setattr(keyboard.termios, 'tcgetattr', no_tty)
    monkeypatch.setattr(keyboard.tty, 'setcbreak', no_tty)
    read, write = os.pipe()
    try:
        with os.fdopen(read, 'r', closefd=False) as pipe:
            assert keyboard.TerminalKeys.open(pipe) is None
    finally:
        os.close(read)
        os.close(write)
    with open(os.devnull) as null:
        assert keyboard.TerminalKeys.open(null) is None
    assert keyboard.TerminalKeys.open(io.StringIO('  ')) is None


def read_until(fd, text, deadline, seen):
    """Read a process's stderr (fd) until `text` appears; fail at the deadline."""
    while text not in seen[0]:
        assert time.monotonic() < deadline, f'never saw {text!r} in:\n{seen[0]}'
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            chunk = os.read(fd, 4096).decode(errors='replace')
            assert chunk, f'the player ended before {text!r}:\n{seen[0]}'
            seen[0] += chunk


@pytest.mark.slow
def test_keys_typed_in_a_real_terminal_pause_and_resume_the_command(tmp_path):
    bag = make_bag(tmp_path / 'b', n=3)
    master, slave = os.openpty()
    before = termios.tcgetattr(slave)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'tskf_ros.bag.player', str(bag), '-r', '0.001', '--topics',
         '/a/power'], stdin=slave, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    seen = ['']
    try:
        deadline = time.monotonic() + TIMEOUT
        fd = proc.stderr.fileno()
        read_until(fd, keyboard.HELP, deadline, seen)
        assert termios.tcgetattr(slave)[3] & termios.ICANON == 0, 'the terminal is in cbreak'
        os.write(master, b' ')
        read_until(fd, ']: paused', deadline, seen)
        os.write(master, b' ')
        read_until(fd, ']: resumed', deadline, seen)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
        seen[0] += proc.stderr.read().decode(errors='replace')   # what it said at the end
        proc.stderr.close()
        after = termios.tcgetattr(slave)
        os.close(master)
        os.close(slave)
    assert proc.returncode == 0, seen[0]
    assert after == before, 'the terminal got its settings back'
