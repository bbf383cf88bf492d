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
The reference of bench/bench_startup.py: a minimal rclpy relay, no filter.

    python bench/minimal_relay.py INPUT_TOPIC OUTPUT_TOPIC

Subscribes to sensor_msgs/msg/Illuminance on INPUT_TOPIC (best effort, as the nodes'
inputs) and publishes each sample's stamp and value as a std_msgs/msg/Float64MultiArray
on OUTPUT_TOPIC (reliable, depth 10, as the nodes' estimates), on a SingleThreadedExecutor,
until Ctrl-C.
"""

import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Illuminance
from std_msgs.msg import Float64MultiArray


def main() -> None:
    """Relay until Ctrl-C."""
    source, target = sys.argv[1:3]
    rclpy.init()
    node = Node('minimal_relay')
    pub = node.create_publisher(Float64MultiArray, target, 10)
    out = Float64MultiArray()

    def relay(msg: Illuminance) -> None:
        out.data = [msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9, msg.illuminance]
        pub.publish(out)

    node.create_subscription(Illuminance, source, relay, qos_profile_sensor_data)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
