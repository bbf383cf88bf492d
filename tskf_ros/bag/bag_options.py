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

"""`ros2 bag` (Jazzy) topic selection and QoS override files, shared by record and play."""

from dataclasses import dataclass, field
import math
from pathlib import Path
import re
from typing import Optional

from rclpy.duration import Duration
from rclpy.qos import (QoSDurabilityPolicy, QoSHistoryPolicy, QoSLivelinessPolicy, QoSProfile,
                       QoSReliabilityPolicy)

from tskf_ros.bag.bag_errors import BagError
from tskf_ros.core.units import NS

import yaml

# s: the longest time in int64 nanoseconds (rosbag2's and rcl's times), whole seconds
MAX_SECONDS = float((2 ** 63 - 1) // NS)
# the only storage this package writes (and, besides sqlite3 bags, reads)
STORAGE_ID = 'mcap'
_POLICIES = {
    'history': QoSHistoryPolicy,
    'reliability': QoSReliabilityPolicy,
    'durability': QoSDurabilityPolicy,
    'liveliness': QoSLivelinessPolicy,
}
_DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')
_VALUES = ('depth', 'avoid_ros_namespace_conventions')


class OptionError(BagError):
    """A bad option value found after parsing (a QoS file, a regular expression)."""


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """
    Split a command line into (the program's own arguments, its --ros-args segments).

    rclpy's remove_ros_args would also take FROM:=TO, rcl's deprecated remap form, which is
    the spelling of rosbag2's own `--remap FROM:=TO`; only --ros-args ... [--] is ROS's here.
    """
    own, ros, inside = [], [], False
    for arg in argv:
        if arg == '--ros-args':
            inside = True
            ros.append(arg)
        elif inside and arg == '--':
            inside = False
            ros.append(arg)
        else:
            (ros if inside else own).append(arg)
    return own, ros


def seconds_ns(flag: str, seconds: float, *, low: float = 0.0, above: bool = False) -> int:
    """
    Return a time option in ns; raise OptionError unless finite, >= low and within int64.

    above: the value must be > low, not only >= it.  rosbag2 holds times in int64 ns, so a
    value of more than MAX_SECONDS (about 292 years) has no meaning there either.
    """
    try:
        value = float(seconds)
    except OverflowError:           # an int beyond any float
        value = math.inf if seconds > 0 else -math.inf
    bad = not math.isfinite(value) or (value <= low if above else value < low)
    if bad or abs(value) > MAX_SECONDS:
        sign = '>' if above else '>='
        raise OptionError(f'{flag} must be a finite number {sign} {low:g} and at most '
                          f'{MAX_SECONDS:.0f} s (int64 nanoseconds), got {seconds}')
    return int(round(value * NS))


def compile_regex(flag: str, pattern: str) -> Optional['re.Pattern']:
    """Compile a --regex style option ('' -> None); raise OptionError naming the flag."""
    if not pattern:
        return None
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise OptionError(f'{flag}: not a regular expression ({exc})') from None


@dataclass
class TopicFilter:
    """Which topic names are taken; `take(name)` says it (see the module doc)."""

    topics: list = field(default_factory=list)
    regex: Optional['re.Pattern'] = None
    exclude_topics: list = field(default_factory=list)
    exclude_regex: Optional['re.Pattern'] = None
    whole_name: bool = False        # play: the regex matches the whole name

    def _matches(self, pattern: 're.Pattern', name: str) -> bool:
        return bool(pattern.fullmatch(name) if self.whole_name else pattern.search(name))

    def take(self, name: str) -> bool:
        """Say whether the topic `name` is selected."""
        if self.topics or self.regex is not None:
            if name not in self.topics and not (
                    self.regex is not None and self._matches(self.regex, name)):
                return False
        if name in self.exclude_topics:
            return False
        return not (self.exclude_regex is not None and self._matches(self.exclude_regex, name))


def _duration(topic: str, key: str, value: object) -> Duration:
    if not isinstance(value, dict) or 'sec' not in value or 'nsec' not in value:
        raise OptionError(f'{topic}: {key} must be {{sec: S, nsec: N}}, got {value!r}')
    try:
        sec, nsec = int(value['sec']), int(value['nsec'])
    except (TypeError, ValueError):
        raise OptionError(f'{topic}: {key} must be integers, got {value!r}') from None
    if sec < 0 or nsec < 0:
        raise OptionError(f'{topic}: {key} may not be negative, got {value!r}')
    return Duration(seconds=sec, nanoseconds=nsec)


def _profile(topic: str, policies: object) -> QoSProfile:
    if not isinstance(policies, dict):
        raise OptionError(f'{topic}: expected a mapping of QoS policies, got {policies!r}')
    kwargs: dict = {}
    for key, value in policies.items():
        if key in _POLICIES:
            try:
                kwargs[key] = _POLICIES[key].get_from_short_key(str(value))
            except KeyError:
                raise OptionError(f'{topic}: {key} {value!r} is not one of '
                                  f'{", ".join(_POLICIES[key].short_keys())}') from None
        elif key in _DURATIONS:
            kwargs[key] = _duration(topic, key, value)
        elif key in _VALUES:
            if isinstance(value, bool) != (key == 'avoid_ros_namespace_conventions') or \
                    not isinstance(value, int) or value < 0:
                raise OptionError(f'{topic}: {key} {value!r} is not valid')
            kwargs[key] = value
        else:
            raise OptionError(f'{topic}: unexpected key {key!r} for a QoS profile')
    kwargs.setdefault('depth', 10)
    return QoSProfile(**kwargs)


def load_qos_overrides(path: Optional[Path]) -> dict:
    """Read a rosbag2 QoS override file: topic -> rclpy QoSProfile ({} for None)."""
    if path is None:
        return {}
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except OSError as exc:
        raise OptionError(f'{path}: {exc.strerror or exc}') from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise OptionError(f'{path}: not YAML ({str(exc).splitlines()[0]})') from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise OptionError(f'{path}: expected topic names mapped to QoS policies')
    try:
        return {str(topic): _profile(str(topic), policies) for topic, policies in doc.items()}
    except OptionError as exc:
        raise OptionError(f'{path}: {exc}') from None
