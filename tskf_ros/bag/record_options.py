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

"""record's command line: `ros2 bag record`'s (Jazzy) options, checked, as the Recorder's."""

import argparse
import datetime
from pathlib import Path
import re
import sys
from typing import Optional, Sequence

from rclpy.parameter import Parameter

from tskf_ros.bag.bag_options import (compile_regex, load_qos_overrides, MAX_SECONDS,
                                      OptionError, seconds_ns, STORAGE_ID, TopicFilter)

EPILOG = """examples:
  record --topics /received_power /true_angle -o /tmp/run1
  record -a -o /tmp/run1 --exclude-regex '^/estimate' -b 50000000
  record --topics /received_power:sensor_msgs/msg/Illuminance   # type given, no wait

The bag is written into a hidden .partial directory and renamed when closed.  Every
--flush-interval s the chunk in progress is written and fsynced: after a SIGKILL or a power
loss, `reindex` makes a bag of the .partial directory.  A full disk stops the recording;
what reached the disk is closed as a valid bag and the command exits 1."""

NODE_NAME = 'recorder'
# a fully qualified topic name (rcl's grammar, without substitutions)
TOPIC_NAME = re.compile(r'/|(/[A-Za-z_][A-Za-z0-9_]*)+')
# s: default interval between flushes (what a SIGKILL or a power loss may lose at most)
FLUSH_INTERVAL = 1.0
# rosbag2's default bag name: the local date and time
DEFAULT_NAME_FORMAT = 'rosbag2_%Y_%m_%d-%H_%M_%S'
# --storage-preset-profile of rosbag2's MCAP plugin -> zstd chunk compression here
PRESET_COMPRESS = {'none': False, 'zstd_fast': True, 'zstd_small': True}


def parse_topics(specs: Sequence[str]) -> tuple[list, dict]:
    """Split NAME or NAME:TYPE specs into names and a name -> type map."""
    names, types = [], {}
    for spec in specs:
        name, _, msgtype = spec.partition(':')
        if not name.startswith('/'):
            name = '/' + name
        if msgtype:
            types[name] = msgtype
        else:
            names.append(name)
    return names, types


def build_parser() -> argparse.ArgumentParser:
    """Return the command line: the spelling, defaults and short options of Jazzy's."""
    parser = argparse.ArgumentParser(
        prog='record', description='Record topics to a rosbag2 MCAP bag (raw, receive time '
        'as log time), with the options of ros2 bag record (Jazzy).', epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('-o', '--output', type=Path,
                        help='bag directory to create (default: rosbag2_YYYY_MM_DD-HH_MM_SS '
                        'in the current directory, from the local date and time)')
    parser.add_argument('-s', '--storage', default=STORAGE_ID, choices=['mcap', 'sqlite3'],
                        help='storage (mcap only: sqlite3 is refused)')
    topics = parser.add_mutually_exclusive_group()
    topics.add_argument('topics_positional', nargs='*', default=[], metavar='[Topic ...]',
                        help='topics to record (deprecated, as in Jazzy: use --topics)')
    topics.add_argument('--topics', nargs='+', default=[], metavar='Topic',
                        help='topics to record: NAME, or NAME:TYPE to subscribe without '
                        'waiting for a publisher (our extra)')
    parser.add_argument('-a', '--all', action='store_true',
                        help='record every topic, discovered as it appears (but hidden '
                        'topics, /rosout and /parameter_events)')
    parser.add_argument('-e', '--regex', default='',
                        help='record the topics whose name contains a match of this regular '
                        'expression (--all overrides it)')
    parser.add_argument('--exclude-regex', default='',
                        help='do not record topics containing a match (on top of --all or '
                        '--regex)')
    parser.add_argument('--exclude-topics', nargs='+', default=[], metavar='Topic',
                        help='topics not to record (on top of --all or --regex)')
    parser.add_argument('--no-discovery', action='store_true',
                        help='record only the topics present at startup')
    parser.add_argument('-p', '--polling-interval', type=int, default=100, metavar='MS',
                        help='ms between looks at the graph for new topics (default 100)')
    parser.add_argument('--qos-profile-overrides-path', type=Path, metavar='YAML',
                        help="subscription QoS per topic (rosbag2's YAML format)")
    parser.add_argument('-b', '--max-bag-size', type=int, default=0, metavar='BYTES',
                        help='split the bag into files of this many bytes of messages '
                        '(0: one file)')
    parser.add_argument('-d', '--max-bag-duration', type=int, default=0, metavar='S',
                        help='split the bag into files of this many seconds (0: one file; '
                        'with -b, whichever is reached first)')
    parser.add_argument('--compression-mode', default='none',
                        choices=['none', 'file', 'message'],
                        help='file or message: zstd-compress the MCAP chunks (what each '
                        'means here: README)')
    parser.add_argument('--compression-format', default='', choices=['zstd'],
                        help='zstd (the only one, as in Jazzy); needs --compression-mode')
    parser.add_argument('--storage-preset-profile', default='none',
                        choices=sorted(PRESET_COMPRESS),
                        help='zstd_fast, zstd_small: zstd chunk compression')
    parser.add_argument('--use-sim-time', action='store_true',
                        help='log times from /clock; nothing is written before the first')
    parser.add_argument('--node-name', default=NODE_NAME, help='the recorder node name')
    parser.add_argument('--custom-data', nargs='*', default=[], metavar='KEY=VALUE',
                        help="entries of metadata.yaml's custom_data")
    parser.add_argument('--overwrite', action='store_true',
                        help='replace an existing bag written by tskf_ros (our extra)')
    parser.add_argument('--flush-interval', type=float, default=FLUSH_INTERVAL, metavar='S',
                        help='write and fsync the chunk in progress every S seconds: what a '
                        f'crash may lose at most (default {FLUSH_INTERVAL:g}; 0: only when '
                        'chunks fill; our extra)')
    return parser


def check_options(parser: argparse.ArgumentParser, opts: argparse.Namespace) -> None:
    """Refuse bad combinations and values (argparse's usage error, exit 2) as rosbag2 does."""
    if opts.topics_positional:
        print('[WARN] [record]: positional topics are deprecated (as in ros2 bag record); '
              'use --topics', file=sys.stderr)
        opts.topics = opts.topics_positional
    for given, flag in ((opts.topics, '--topics'), (opts.regex, '--regex')):
        if opts.all and given:
            print(f'[WARN] [record]: --all overrides {flag} (as in ros2 bag record)',
                  file=sys.stderr)
    if not (opts.all or opts.topics or opts.regex):
        parser.error('need --all, --topics or --regex')
    if opts.exclude_regex and not (opts.all or opts.regex):
        parser.error('--exclude-regex needs --all or --regex')
    if opts.exclude_topics and not (opts.all or opts.regex):
        parser.error('--exclude-topics needs --all or --regex')
    if opts.compression_format and opts.compression_mode == 'none':
        parser.error('--compression-format needs --compression-mode file or message')
    if opts.max_bag_size < 0:
        parser.error(f'--max-bag-size must be >= 0, got {opts.max_bag_size}')
    try:
        # times are int64 ns as in rosbag2: 1e308 s is refused, not an overflow
        seconds_ns('--max-bag-duration', opts.max_bag_duration)
        seconds_ns('--flush-interval', opts.flush_interval)
        if not 0 < opts.polling_interval <= MAX_SECONDS * 1000:
            raise OptionError(f'--polling-interval must be > 0 ms and at most '
                              f'{MAX_SECONDS * 1000:.0f}, got {opts.polling_interval}')
    except OptionError as exc:
        parser.error(str(exc))
    names, types = parse_topics(opts.topics + opts.exclude_topics)
    bad = [n for n in names + list(types) if not TOPIC_NAME.fullmatch(n)]
    if bad:
        parser.error(f'not a topic name: {bad[0]}')
    for pair in opts.custom_data:
        if '=' not in pair or not pair.partition('=')[0]:
            parser.error(f'--custom-data: expected KEY=VALUE, got {pair!r}')


def recorder_options(opts: argparse.Namespace) -> dict:
    """Return the Recorder's keyword arguments for parsed options (raises OptionError)."""
    if opts.storage != STORAGE_ID:
        raise OptionError(f'--storage {opts.storage}: this recorder writes mcap only')
    names, types = parse_topics(opts.topics)
    # a NAME:TYPE topic is one of those asked for, as a bare NAME is
    topic_filter = TopicFilter(topics=[] if opts.all else names + list(types),
                               regex=None if opts.all else compile_regex('--regex', opts.regex),
                               exclude_topics=parse_topics(opts.exclude_topics)[0],
                               exclude_regex=compile_regex('--exclude-regex',
                                                           opts.exclude_regex))
    everything = opts.all and not opts.exclude_topics and not opts.exclude_regex
    return {
        'topics': None if everything else names, 'types': {} if opts.all else types,
        'topic_filter': None if everything else topic_filter,
        'overwrite': opts.overwrite,
        'compress': (opts.compression_mode != 'none'
                     or PRESET_COMPRESS[opts.storage_preset_profile]),
        'discovery_period': opts.polling_interval / 1000.0,
        'discovery': not opts.no_discovery,
        'flush_interval': opts.flush_interval,
        'qos_overrides': load_qos_overrides(opts.qos_profile_overrides_path),
        'max_bag_size': opts.max_bag_size, 'max_bag_duration': float(opts.max_bag_duration),
        'custom_data': dict(pair.split('=', 1) for pair in opts.custom_data),
        'node_name': opts.node_name,
        'parameter_overrides': ([Parameter('use_sim_time', value=True)]
                                if opts.use_sim_time else None)}


def default_output(now: Optional[datetime.datetime] = None) -> Path:
    """Return rosbag2's default bag name, from the local date and time."""
    return Path((now or datetime.datetime.now()).strftime(DEFAULT_NAME_FORMAT))
