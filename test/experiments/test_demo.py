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

"""The demo's node processes start through the console scripts' runner (quiet on Ctrl-C)."""

import os
import subprocess
import sys

from bag.helpers import CONFIG, TIMEOUT
import pytest

from tskf_ros.experiments import demo
from tskf_ros.tools import console


@pytest.mark.parametrize('node', ['timescale_estimator', 'power_meter_simulator',
                                  'led_link_simulator', 'alignment'])
def test_each_node_command_runs_that_nodes_console_script(node):
    cmd = demo.node_command(node, CONFIG / 'x.yaml', seed=1, loop=False)
    assert cmd[:2] == [sys.executable, '-c'] and node in console.TOOLS
    assert cmd[2] == f'from tskf_ros.tools.console import {node}; {node}()'
    assert cmd[3:] == ['--ros-args', '--params-file', str(CONFIG / 'x.yaml'),
                       '-p', 'seed:=1', '-p', 'loop:=false']


def test_a_node_command_starts_the_node():
    # --help in place of --ros-args: the node's own usage, exit 0
    cmd = demo.node_command('timescale_estimator', CONFIG / 'owc_estimator.yaml')[:3]
    proc = subprocess.run([*cmd, '--help'], env=dict(os.environ), capture_output=True,
                          text=True, timeout=TIMEOUT)
    assert proc.returncode == 0 and 'usage' in proc.stdout and proc.stderr == '', proc.stderr
