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

"""What the bag tools say of a bag they cannot use: errors, damage, exit status, paths."""

from dataclasses import dataclass
import errno
import os
from pathlib import Path
import sys
from typing import Callable, Optional, Union

__all__ = ['BagEmptyError', 'BagError', 'BagFormatError', 'BagNotFoundError', 'check_exists',
           'Damage', 'error_exit', 'EXIT_DAMAGED', 'EXIT_INTERRUPTED', 'exit_status',
           'MetadataError', 'one_line', 'resolved', 'run_main']

PathLike = Union[str, os.PathLike]
# exit status of a command whose input bag was damaged (what it could read was used)
EXIT_DAMAGED = 3
# exit status after Ctrl-C (128 + SIGINT, as a shell reports it)
EXIT_INTERRUPTED = 130
_LOOP = 'a symlink loop (too many levels of symbolic links)'


class BagError(Exception):
    """A bag that cannot be read; str() is one line naming the file and the problem."""


class BagNotFoundError(BagError):
    """The bag, or a file its metadata lists, does not exist."""


class BagEmptyError(BagError):
    """A storage file of zero bytes, or a bag without messages."""


class MetadataError(BagError):
    """metadata.yaml is missing or unreadable."""


class BagFormatError(BagError):
    """Not an MCAP or sqlite3 rosbag2 file, or a storage this reader does not know."""


@dataclass(frozen=True)
class Damage:
    """Where reading stopped: the file, the byte offset, the problem, messages before."""

    path: str
    offset: int
    problem: str
    messages_before: int

    def __str__(self) -> str:
        """One line: file, problem, offset and what was read before."""
        return (f'{self.path}: {self.problem} at byte {self.offset}; the '
                f'{self.messages_before} message(s) before it were read')


def error_exit(prog: str, exc: Exception, path: object = '') -> int:
    """Print a command's error in one line (an OSError names its file) and return 1."""
    if isinstance(exc, OSError):
        print(f'{prog}: error: {exc.filename or path}: {exc.strerror or exc}', file=sys.stderr)
    else:
        print(f'{prog}: error: {exc}', file=sys.stderr)
    return 1


def exit_status(prog: str, damage: Optional['Damage'], what: str) -> int:
    """Return 0, or print the damage in one line (prefixed by prog and what) and EXIT_DAMAGED."""
    if damage is None:
        return 0
    print(f'{prog}: {what}: {damage}', file=sys.stderr)
    return EXIT_DAMAGED


def resolved(path: PathLike) -> Path:
    """Return the absolute path without symlinks; a symlink loop is a BagNotFoundError."""
    try:
        return Path(path).resolve()
    except RuntimeError:        # Python < 3.13's symlink loop
        raise BagNotFoundError(f'{path}: {_LOOP}') from None
    except OSError as exc:      # a loop that resolve() reports as ELOOP
        raise BagNotFoundError(f'{path}: {_LOOP} ({one_line(exc)})') from None


def check_exists(path: Path, what: str = 'bag (file or directory)') -> None:
    """Raise BagNotFoundError (a symlink loop, a dangling symlink) unless `path` exists."""
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise BagNotFoundError(f'{path}: {_LOOP}') from None
        if Path(path).is_symlink():
            raise BagNotFoundError(f'{path}: a symlink to nothing ({os.readlink(path)})') \
                from None
        raise BagNotFoundError(f'{path}: no such {what}') from None


def run_main(prog: str, main: Callable[[], int]) -> int:
    """
    Run a command's main; Ctrl-C is one line and exit status 130 (128 + SIGINT).

    The commands write every output to a temporary name first and delete it on any
    exception, so nothing half-written is left by the interrupt.
    """
    try:
        return main()
    except KeyboardInterrupt:
        print(f'{prog}: interrupted; no unfinished output is kept', file=sys.stderr)
        return EXIT_INTERRUPTED


def one_line(exc: BaseException) -> str:
    """Return the first line of an exception's text (its strerror for an OSError)."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).splitlines()
    return text[0] if text else type(exc).__name__
