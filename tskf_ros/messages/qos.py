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

"""The QoS profiles of every topic this package publishes or subscribes to, in one place."""

from typing import Sequence

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, qos_profile_sensor_data, QoSPolicyKind,
                       QoSProfile, ReliabilityPolicy)
from rclpy.qos_overriding_options import QoSOverridingOptions

__all__ = ['DEFAULT_DEPTH', 'DIAGNOSTICS_TOPIC', 'matching_qos', 'overridable',
           'reliable_qos', 'SENSOR_OUTPUT_QOS', 'sensor_input_qos', 'TRUTH_QOS']

DIAGNOSTICS_TOPIC = '/diagnostics'
# rclpy's system default depth: what /diagnostics and forward_command_controller use
DEFAULT_DEPTH = 10
# a simulated or real sensor publishes as a driver does: rclpy's sensor-data profile
SENSOR_OUTPUT_QOS = qos_profile_sensor_data


def sensor_input_qos(depth: int) -> QoSProfile:
    """
    Return the QoS for a sensor input: best effort, keep last depth.

    A best-effort subscription matches reliable and best-effort publishers alike, so the
    node takes a real driver's sensor-data stream as well as a reliable bag player.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT)


def reliable_qos(depth: int) -> QoSProfile:
    """Return the QoS of an output every sample of which matters: reliable, keep last depth."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE)


def overridable() -> QoSOverridingOptions:
    """
    Return the options that let `qos_overrides.<topic>.publisher.*` parameters set a QoS.

    History, depth, reliability (rclpy's with_default_policies()) and durability, so that
    a late subscriber can be served with transient_local.
    """
    return QoSOverridingOptions(policy_kinds=(
        QoSPolicyKind.HISTORY, QoSPolicyKind.DEPTH, QoSPolicyKind.RELIABILITY,
        QoSPolicyKind.DURABILITY))


# the evaluation truth of both simulators: reliable, so that a plot has every point
TRUTH_QOS = reliable_qos(100)


def matching_qos(offered: Sequence[QoSProfile], *, history: HistoryPolicy,
                 depth: int) -> QoSProfile:
    """
    Return a subscription QoS that matches every publisher of a topic (their `offered` QoS).

    Reliable if every publisher is, else best effort (which matches both); transient local
    if every publisher is (a late subscriber then gets what they keep), else volatile.
    """
    reliable = bool(offered) and all(
        p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
    latched = bool(offered) and all(
        p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        history=history, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
