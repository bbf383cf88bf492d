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
The OWC pipeline: the power-meter simulator and the time-scale estimator.

    ros2 launch tskf_ros owc_pipeline.launch.py
    ros2 launch tskf_ros owc_pipeline.launch.py namespace:=bench1 log_level:=debug \
        params_file:=/path/to/my_estimator.yaml

The simulator publishes `received_power`; the estimator reads its neutral `measurement`
topic, remapped here to `received_power` (the launch file restores the OWC name).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the simulator and the estimator, in one namespace."""
    config = os.path.join(get_package_share_directory('tskf_ros'), 'config')
    namespace = LaunchConfiguration('namespace')
    use_sim_time = LaunchConfiguration('use_sim_time')
    log_level = LaunchConfiguration('log_level')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of both nodes'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(config, 'owc_estimator.yaml'),
                              description='parameters of the estimator'),
        DeclareLaunchArgument('simulator_params_file',
                              default_value=os.path.join(config,
                                                         'power_meter_simulator.yaml'),
                              description='parameters of the simulator'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='follow /clock (a bag played with --clock)'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='debug, info, warn or error'),
        Node(package='tskf_ros', executable='power_meter_simulator',
             name='power_meter_simulator', namespace=namespace, output='screen',
             parameters=[LaunchConfiguration('simulator_params_file'),
                         {'use_sim_time': use_sim_time}],
             arguments=['--ros-args', '--log-level', log_level]),
        Node(package='tskf_ros', executable='timescale_estimator',
             name='timescale_estimator', namespace=namespace, output='screen',
             parameters=[LaunchConfiguration('params_file'), {'use_sim_time': use_sim_time}],
             remappings=[('measurement', 'received_power')],
             arguments=['--ros-args', '--log-level', log_level]),
    ])
