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
The experiments' numeric option types and the options the Monte Carlo experiments share.

Any value out of range is one usage line.
"""

import argparse
import math
import os
from typing import Callable, Optional, Sequence

# seeds: what numpy's default_rng takes as one 32-bit word (every documented seed fits)
SEED_LIMIT = 2 ** 32
# the Monte Carlo experiments' largest runs per point and steps per run (100 times the
# papers'), and their longest time step in s (the loop runs at 20 Hz: 0.05)
MAX_RUNS = 100_000
MAX_STEPS = 100_000
MAX_DT = 60.0
# the LED experiments' noise standard deviations (V: over 30 times the 3 V peak) and drift
# rates (deg/s: a turn a second); beyond them the intensity model overflows to NaN
MAX_NOISE = 100.0
MAX_RATE = 360.0


def seed(text: str) -> int:
    """Parse a random seed: an integer in [0, 2**32)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if not 0 <= value < SEED_LIMIT:
        raise argparse.ArgumentTypeError(f'a seed must be in [0, 2**32), got {text}')
    return value


def count(low: int, high: int) -> Callable[[str], int]:
    """Return an argparse type of an integer in [low, high]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f'must be in [{low}, {high}], got {text}')
        return value
    parse.__name__ = 'count'
    return parse


def number(low: float, high: float, *, open_low: bool = False) -> Callable[[str], float]:
    """Return an argparse type of a finite float in [low, high] ((low, high] if open_low)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
        above = value > low if open_low else value >= low
        if not (math.isfinite(value) and above and value <= high):
            raise argparse.ArgumentTypeError(
                f'must be a finite number in {"(" if open_low else "["}{low:g}, {high:g}], '
                f'got {text}')
        return value
    parse.__name__ = 'number'
    return parse


def numbers(low: float, high: float) -> Callable[[str], list[float]]:
    """Return an argparse type of a comma-separated list of finite floats in [low, high]."""
    one = number(low, high)

    def parse(text: str) -> list[float]:
        values = [one(part) for part in text.split(',') if part.strip()]
        if not values:
            raise argparse.ArgumentTypeError(f'need a comma-separated list of numbers, '
                                             f'got {text!r}')
        return values
    parse.__name__ = 'numbers'
    return parse


# the LED experiments' option types
noise_volts = number(0.0, MAX_NOISE)
noise_list = numbers(0.0, MAX_NOISE)
rate_deg_s = number(0.0, MAX_RATE)
angle_deg = number(-180.0, 180.0)


def add_runs(p: argparse.ArgumentParser, default: int, per: str) -> None:
    """Add --runs, the Monte Carlo runs per `per` (a point, a noise level, ...)."""
    p.add_argument('--runs', type=count(1, MAX_RUNS), default=default,
                   help=f'runs per {per} ({default})')


def add_noise_levels(p: argparse.ArgumentParser, default: Sequence[float]) -> None:
    """Add --noise-levels, the LED experiments' comma list of noise levels in volts."""
    shown = ','.join(f'{v:g}' for v in default) if len(default) <= 3 else \
        f'{default[0]:g},{default[1]:g},...,{default[-1]:g}'
    p.add_argument('--noise-levels', type=noise_list, default=list(default),
                   help=f'comma list of noise standard deviations in volts ({shown})')


def add_run_options(p: argparse.ArgumentParser, dt: Optional[float] = None) -> None:
    """Add the Monte Carlo options --steps, --dt (if dt: its default, s), --seed, --workers."""
    p.add_argument('--steps', type=count(1, MAX_STEPS), default=400,
                   help='steps per run (400 = 20 s)')
    if dt is not None:
        p.add_argument('--dt', type=number(0.0, MAX_DT, open_low=True), default=dt,
                       help=f'time step, s ({dt:g})')
    p.add_argument('--seed', type=seed, default=0)
    p.add_argument('--workers', type=count(1, 1024), default=os.cpu_count() or 1,
                   help='processes the points run on (default: every core); the results do '
                        'not depend on it')


def add_scheduler(p: argparse.ArgumentParser) -> None:
    """Add --scheduler, a Dask scheduler whose workers run the Monte Carlo's tasks."""
    p.add_argument('--scheduler', metavar='ADDRESS',
                   help='address of a Dask scheduler (e.g. tcp://localhost:8786): its workers '
                        'run the points instead of --workers processes (they need this '
                        'package); the results do not depend on it')
