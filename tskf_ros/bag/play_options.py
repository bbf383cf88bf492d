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

"""play's command line: the options of `ros2 bag play` (Jazzy), checked, as the Player's."""

import argparse
import math
from pathlib import Path
from typing import Sequence

from tskf_ros.bag.bag_options import (compile_regex, MAX_SECONDS, OptionError, seconds_ns,
                                      TopicFilter)
from tskf_ros.bag.reader import BagError
from tskf_ros.core.units import NS

EPILOG = """examples:
  play bags/owc_cai_td_1hz --rate 10 --clock
  play bags/owc_cai_td_1hz --topics /received_power -m /received_power:=/power --loop
  play bags/owc_ge_1khz --start-offset 30 --playback-duration 5 -p

The stored bytes are published as they are, in storage (log time) order, at bag time =
start + offset + rate x wall time (frozen while paused).  Keys when stdin is a terminal:
space pause/resume, cursor right next message, cursor up/down rate +-0.1; services
~/pause, ~/resume, ~/toggle_paused, ~/play_next."""

# Hz: /clock rate of a bare --clock (rosbag2 Jazzy)
CLOCK_HZ = 40.0
# ms: how long play waits at the end for reliable subscribers' acknowledgements by default
WAIT_ACKED_MS = 1000


class PlayerError(BagError):
    """Bad options for a bag: an unknown topic, a bad remap, an offset past the end."""


def parse_remaps(specs: Sequence[str]) -> dict:
    """Parse FROM:=TO remaps."""
    out = {}
    for spec in specs:
        src, sep, dst = spec.partition(':=')
        if not sep or not src or not dst:
            raise PlayerError(f'bad remap {spec!r}: expected FROM:=TO')
        out[src] = dst
    return out


def build_parser() -> argparse.ArgumentParser:
    """Return the command line: the spelling, defaults and short options of Jazzy's."""
    parser = argparse.ArgumentParser(
        prog='play', description='Publish a bag at its recorded pace, with the options of '
        'ros2 bag play (Jazzy).', epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('-s', '--storage', default='', choices=['mcap', 'sqlite3'],
                        help="the bag's storage (default: detected)")
    parser.add_argument('-r', '--rate', type=float, default=1.0, help='speed factor (> 0)')
    parser.add_argument('--topics', nargs='+', default=[], metavar='topic',
                        help='play only these topics')
    parser.add_argument('-e', '--regex', '--topics-regex', default='', dest='regex',
                        help='play only topics whose whole name matches this regular '
                        'expression (with --topics: either)')
    parser.add_argument('-x', '--exclude-regex', default='',
                        help='do not play topics whose whole name matches')
    parser.add_argument('--exclude-topics', nargs='+', default=[], metavar='topic',
                        help='topics not to play')
    parser.add_argument('--qos-profile-overrides-path', type=Path, metavar='YAML',
                        help="publisher QoS per topic (rosbag2's YAML format)")
    parser.add_argument('-l', '--loop', action='store_true', help='play again at the end')
    parser.add_argument('--remap', '-m', nargs='+', default=[], metavar='FROM:=TO',
                        help='topic remaps')
    parser.add_argument('--clock', type=float, nargs='?', const=CLOCK_HZ, default=0.0,
                        metavar='HZ', help=f'publish /clock at HZ (bare: {CLOCK_HZ:g}; '
                        'default: not published)')
    parser.add_argument('-d', '--delay', type=float, default=0.0,
                        help='seconds to wait before playing (lets subscribers match)')
    parser.add_argument('--playback-duration', type=float, default=-1.0, metavar='S',
                        help='play this many seconds of the bag (negative: all)')
    until = parser.add_mutually_exclusive_group()
    until.add_argument('--playback-until-sec', type=float, default=-1.0, metavar='T',
                       help='play up to this log time, s since the epoch (negative: all)')
    until.add_argument('--playback-until-nsec', type=int, default=-1, metavar='T',
                       help='play up to this log time, ns since the epoch (negative: all)')
    parser.add_argument('--disable-keyboard-controls', action='store_true',
                        help='do not read keys from a terminal stdin')
    parser.add_argument('-p', '--start-paused', action='store_true',
                        help='start paused (resume with space or ~/resume)')
    parser.add_argument('--start-offset', type=float, default=0.0,
                        help='seconds into the bag to start from')
    parser.add_argument('--wait-for-all-acked', type=int, default=WAIT_ACKED_MS, metavar='MS',
                        help='at the end, wait until every reliable subscriber has '
                        'acknowledged every message, or MS ms have passed (0: no limit; '
                        f"default {WAIT_ACKED_MS}, rosbag2's is not to wait)")
    return parser


def player_options(parser: argparse.ArgumentParser, opts: argparse.Namespace) -> dict:
    """Check parsed options (usage error, exit 2) and return the Player's keyword arguments."""
    for flag, value in (('--rate', opts.rate), ('--clock', opts.clock)):
        if not math.isfinite(value) or value < 0 or (value == 0 and flag == '--rate'):
            parser.error(f'{flag} must be a finite number {"> 0" if flag == "--rate" else ">= 0"}'
                         f', got {value}')
    try:
        # times are int64 ns as in rosbag2: 1e308 s is refused, not an overflow
        seconds_ns('--start-offset', opts.start_offset)
        seconds_ns('--delay', opts.delay)
        if opts.clock > 0:
            seconds_ns('--clock period (1/HZ)', 1.0 / opts.clock, above=True)
        for flag, value in (('--playback-duration', opts.playback_duration),
                            ('--playback-until-sec', opts.playback_until_sec)):
            if not value < 0:           # negative: no limit (nan is refused here)
                seconds_ns(flag, value)
        if not 0 <= opts.wait_for_all_acked <= MAX_SECONDS * 1000:
            raise OptionError(f'--wait-for-all-acked must be >= 0 ms (0: no limit) and at '
                              f'most {MAX_SECONDS * 1000:.0f}, got {opts.wait_for_all_acked}')
        topic_filter = TopicFilter(
            topics=list(opts.topics), regex=compile_regex('--regex', opts.regex),
            exclude_topics=list(opts.exclude_topics),
            exclude_regex=compile_regex('--exclude-regex', opts.exclude_regex),
            whole_name=True)
    except BagError as exc:
        parser.error(str(exc))
    until = (int(round(opts.playback_until_sec * NS)) if opts.playback_until_sec >= 0
             else opts.playback_until_nsec)
    return {'rate': opts.rate, 'loop': opts.loop, 'start_offset': opts.start_offset,
            'topic_filter': topic_filter, 'remap': parse_remaps(opts.remap),
            'clock_hz': opts.clock, 'delay': opts.delay, 'start_paused': opts.start_paused,
            'playback_duration': opts.playback_duration, 'playback_until_ns': until,
            'storage': opts.storage}
