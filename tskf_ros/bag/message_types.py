"""Message types and QoS profiles as rclpy, rosbags and the rosbag2 metadata see them."""

import importlib
from typing import Any

from rclpy.duration import Duration
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile,
                       ReliabilityPolicy)
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.typesys import get_typestore, Stores
from rosbags.typesys.store import Typestore

__all__ = ['BagTypeError', 'message_class', 'qos_from_rclpy', 'qos_to_rclpy', 'typestore']

_STORE = None


class BagTypeError(LookupError):
    """A message type that is not installed here (no Python class or no definition)."""


def typestore() -> Typestore:
    """Return the shared rosbags typestore of ROS 2 Jazzy (common_interfaces and more)."""
    global _STORE
    if _STORE is None:
        _STORE = get_typestore(Stores.ROS2_JAZZY)
    return _STORE


def message_class(msgtype: str) -> Any:
    """
    Return the rclpy message class of a type name such as 'sensor_msgs/msg/Illuminance'.

    Raises BagTypeError if the name is malformed or its package is not installed.
    """
    parts = msgtype.split('/')
    if len(parts) != 3 or not all(parts):
        raise BagTypeError(f'{msgtype!r} is not a message type name (pkg/msg/Name)')
    try:
        module = importlib.import_module(f'{parts[0]}.{parts[1]}')
        return getattr(module, parts[2])
    except (ImportError, AttributeError):
        raise BagTypeError(f'message type {msgtype} is not installed here') from None


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
