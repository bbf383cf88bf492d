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
The two-axis LED alignment loop: the simulator and the aligner of a pan-tilt mount.

Both nodes run with `axes: 2` (config/pan_tilt_loop.yaml holds both nodes' parameters): the
simulator's source drifts in azimuth and elevation, the alignment node's conical-scan EKF
estimates the two pointing errors and commands the mount's two joints.

    ros2 launch tskf_ros pan_tilt_loop.launch.py
    ros2 launch tskf_ros pan_tilt_loop.launch.py namespace:=rig2 log_level:=warn
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the two-axis link simulator and the two-axis aligner, on the namespace's topics."""
    config = os.path.join(get_package_share_directory('tskf_ros'), 'config')
    namespace = LaunchConfiguration('namespace')
    use_sim_time = LaunchConfiguration('use_sim_time')
    log_level = LaunchConfiguration('log_level')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='pan_tilt',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(config, 'pan_tilt_loop.yaml'),
                              description='parameters of the alignment node (axes: 2)'),
        DeclareLaunchArgument('simulator_params_file',
                              default_value=os.path.join(config, 'pan_tilt_loop.yaml'),
                              description='parameters of the LED link simulator (axes: 2)'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='follow /clock'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='debug, info, warn or error'),
        Node(package='tskf_ros', executable='led_link_simulator', name='led_link_simulator',
             namespace=namespace, output='screen',
             parameters=[LaunchConfiguration('simulator_params_file'),
                         {'use_sim_time': use_sim_time}],
             arguments=['--ros-args', '--log-level', log_level]),
        Node(package='tskf_ros', executable='alignment', name='alignment',
             namespace=namespace, output='screen',
             parameters=[LaunchConfiguration('params_file'), {'use_sim_time': use_sim_time}],
             arguments=['--ros-args', '--log-level', log_level]),
    ])
