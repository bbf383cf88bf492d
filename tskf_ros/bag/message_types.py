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

"""Message types and QoS profiles as rclpy, rosbags and the rosbag2 metadata see them."""

import importlib
import importlib.util
from pathlib import Path
import re
from typing import Any

from rclpy.duration import Duration
from rclpy.exceptions import NoTypeSupportImportedException
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile,
                       ReliabilityPolicy)
from rclpy.type_support import check_is_valid_msg_type
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.typesys import get_typestore, Stores
from rosbags.typesys.store import Typestore

__all__ = ['BagTypeError', 'DESERIALIZE_ERRORS', 'interface_package', 'message_class',
           'qos_from_rclpy', 'qos_to_rclpy', 'typestore']

_STORE = None
# exceptions rclpy's deserialize_message raises on bytes that are not the type
DESERIALIZE_ERRORS = (RuntimeError, ValueError, TypeError)
# package/msg/Name: the ROS 2 interface name grammar (rosidl_adapter, REP 144)
TYPE_NAME = re.compile(r'[a-z][a-z0-9_]*/msg/[A-Z][A-Za-z0-9]*')


class BagTypeError(LookupError):
    """A message type that is not installed here (no Python class or no definition)."""


def typestore() -> Typestore:
    """Return the shared rosbags typestore of ROS 2 Jazzy (common_interfaces and more)."""
    global _STORE
    if _STORE is None:
        _STORE = get_typestore(Stores.ROS2_JAZZY)
    return _STORE


def interface_package(pkg: str) -> bool:
    """
    Say whether `pkg` is an installed rosidl-generated interface package, without importing it.

    Such a package is a directory with a `msg` subpackage and the generated type support
    libraries (<pkg>_s__rosidl_typesupport_c...); nothing else (`os`, `this`, any module
    that runs code when imported) is ever imported by message_class.
    """
    try:
        spec = importlib.util.find_spec(pkg)
    except (ImportError, ValueError):
        return False
    if spec is None or not spec.submodule_search_locations:
        return False
    for where in spec.submodule_search_locations:
        top = Path(where)
        if ((top / 'msg' / '__init__.py').is_file()
                and any(top.glob(f'{pkg}_s__rosidl_typesupport_c*'))):
            return True
    return False


def message_class(msgtype: str) -> Any:
    """
    Return the rclpy message class of a type name such as 'sensor_msgs/msg/Illuminance'.

    The name must follow the ROS interface name grammar (package/msg/Name) and name an
    installed interface package (interface_package); raises BagTypeError otherwise,
    without importing anything.
    """
    if not isinstance(msgtype, str) or not TYPE_NAME.fullmatch(msgtype):
        raise BagTypeError(f'{msgtype!r} is not a message type name (package/msg/Name)')
    pkg, sub, name = msgtype.split('/')
    if not interface_package(pkg):
        raise BagTypeError(f'message type {msgtype} is not installed here '
                           f'(no interface package {pkg})')
    try:
        module = importlib.import_module(f'{pkg}.{sub}')
        cls = getattr(module, name)
    except (ImportError, AttributeError):
        raise BagTypeError(f'message type {msgtype} is not installed here') from None
    try:
        check_is_valid_msg_type(cls)
    except (AttributeError, RuntimeError, NoTypeSupportImportedException):
        raise BagTypeError(f'{msgtype} is not a ROS message class') from None
    return cls


def _time(duration: Duration) -> QosTime:
    sec, nsec = divmod(int(duration.nanoseconds), 1_000_000_000)
    return QosTime(sec, nsec)


def qos_from_rclpy(profile: QoSProfile) -> Qos:
    """Convert an rclpy QoSProfile into the rosbags Qos written to metadata.yaml."""
    return Qos(history=QosHistory(int(profile.history)), depth=int(profile.depth),
               reliability=QosReliability(int(profile.reliability)),
               durability=QosDurability(int(profile.durability)),
               deadline=_time(profile.deadline), lifespan=_time(profile.lifespan),
               liveliness=QosLiveliness(int(profile.liveliness)),
               liveliness_lease_duration=_time(profile.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions))


def qos_to_rclpy(qos: Qos, *, depth: int) -> QoSProfile:
    """Convert a recorded Qos into a publisher profile (history KEEP_LAST of `depth`)."""
    reliability = ReliabilityPolicy(qos.reliability.value)
    if reliability not in (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT):
        reliability = ReliabilityPolicy.RELIABLE
    durability = DurabilityPolicy(qos.durability.value)
    if durability not in (DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL):
        durability = DurabilityPolicy.VOLATILE
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability,
                      durability=durability, liveliness=LivelinessPolicy.AUTOMATIC)
