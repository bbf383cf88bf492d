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
Replay a bag into the estimator on the bag's clock (use_sim_time).

    ros2 launch tskf_ros replay_estimator.launch.py bag:=/path/to/bag rate:=10

`play` publishes the bag's topics and /clock; the estimator follows /clock, so its
diagnostics and clock-jump handling run on bag time.  Its `measurement` topic is remapped
to the bag's measurement topic (`topic`, /received_power by default).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    """Return the player (with /clock) and the estimator on sim time."""
    share = get_package_share_directory('tskf_ros')
    namespace = LaunchConfiguration('namespace')
    log_level = LaunchConfiguration('log_level')
    return LaunchDescription([
        DeclareLaunchArgument('bag', default_value=os.path.join(share, 'bags',
                                                                'owc_cai_td_1hz'),
                              description='bag directory to replay'),
        DeclareLaunchArgument('rate', default_value='1.0', description='replay speed'),
        DeclareLaunchArgument('topic', default_value='/received_power',
                              description="the bag's measurement topic"),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of the estimator'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config',
                                                         'owc_estimator.yaml'),
                              description='parameters of the estimator'),
        DeclareLaunchArgument('use_sim_time', default_value='true',
                              description='the estimator follows /clock from the player'),
        DeclareLaunchArgument('log_level', default_value='info',
                              description='debug, info, warn or error'),
        Node(package='tskf_ros', executable='play', name='player', output='screen',
             arguments=[LaunchConfiguration('bag'), '--rate', LaunchConfiguration('rate'),
                        '--clock', '100']),
        Node(package='tskf_ros', executable='timescale_estimator',
             name='timescale_estimator', namespace=namespace, output='screen',
             parameters=[LaunchConfiguration('params_file'),
                         {'use_sim_time': LaunchConfiguration('use_sim_time')}],
             remappings=[('measurement', LaunchConfiguration('topic'))],
             arguments=['--ros-args', '--log-level', log_level]),
    ])
