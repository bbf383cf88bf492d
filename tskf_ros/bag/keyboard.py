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

"""Keyboard controls of `play` (rosbag2's keys): space, cursor right, cursor up and down."""

import os
import select
import sys
import termios
import tty
from typing import Optional

# the bytes a terminal sends for each key, and what the player does
KEYS = {
    b' ': 'toggle_paused',
    b'\x1b[C': 'play_next',        # cursor right
    b'\x1b[A': 'faster',           # cursor up
    b'\x1b[B': 'slower',           # cursor down
}
# rate change per cursor up or down (rosbag2: get_rate() +- 0.1)
RATE_STEP = 0.1
HELP = 'keys: space pause/resume, -> next message (paused), up/down rate +-0.1'


class KeyHandler:
    """Map typed bytes to the player's toggle_paused, play_next and set_rate."""

    def __init__(self, player) -> None:
        self.player = player
        self._pending = b''

    def feed(self, data: bytes) -> list:
        """Act on the keys in data (an escape sequence may be split); return the actions."""
        buf = self._pending + data
        done = []
        while buf:
            for seq, action in KEYS.items():
                if buf.startswith(seq):
                    self._act(action)
                    done.append(action)
                    buf = buf[len(seq):]
                    break
            else:
                if any(seq.startswith(buf) for seq in KEYS if len(seq) > len(buf)):
                    break           # the start of an escape sequence: wait for the rest
                buf = buf[1:]       # a key without a meaning
        self._pending = buf
        return done

    def _act(self, action: str) -> None:
        if action == 'toggle_paused':
            self.player.toggle_paused()
        elif action == 'play_next':
            self.player.play_next()
        else:
            step = RATE_STEP if action == 'faster' else -RATE_STEP
            self.player.set_rate(round(self.player.rate + step, 9))


class TerminalKeys:
    """Unbuffered, non-blocking key reading from a terminal stdin; `close()` restores it."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)

    @classmethod
    def open(cls, stream=None) -> Optional['TerminalKeys']:  # noqa: A003
        """Return the reader for a terminal stream (stdin by default), None for anything else."""
        stream = sys.stdin if stream is None else stream
        try:
            if stream is None or not stream.isatty():
                return None
            return cls(stream.fileno())
        except (OSError, ValueError, termios.error):
            return None

    def read(self) -> bytes:
        """Return what was typed since the last call (b'' if nothing), without waiting."""
        data = b''
        while select.select([self.fd], [], [], 0)[0]:
            chunk = os.read(self.fd, 64)
            if not chunk:
                break
            data += chunk
        return data

    def close(self) -> None:
        """Give the terminal back its settings."""
        termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
