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
The launch files name only executables and parameter files the package installs.

`launch` and `launch_ros` are not available as wheels, so the files are read (ast), not
run: every `Node(package='tskf_ros', executable=...)` must be a console script of
setup.py (what colcon installs to lib/tskf_ros; test_colcon_build checks the installed
tree too), every '*.yaml' a file of config/, every launch argument must be declared
before use, and the usual arguments (namespace, params_file, use_sim_time, log_level)
must exist.  Where launch_ros imports, the files are also loaded for real.
"""

import ast
import importlib.util
import json
from pathlib import Path

from entry_points import console_scripts
import pytest

from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages import estimator_interface as estimator

REPO = Path(__file__).resolve().parents[2]
LAUNCH = sorted((REPO / 'launch').glob('*.launch.py'))
USUAL = {'namespace', 'params_file', 'use_sim_time', 'log_level'}


def calls(tree, name):
    """Every call of `name(...)` in the tree, as {keyword: node} plus positional args."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == name:
            yield node


def keyword(call, name):
    for kw in call.keywords:
        if kw.arg == name:
            return kw.value
    return None


def test_there_are_four_launch_files():
    assert [p.name for p in LAUNCH] == ['led_loop.launch.py', 'owc_pipeline.launch.py',
                                        'pan_tilt_loop.launch.py',
                                        'replay_estimator.launch.py']


@pytest.mark.parametrize('path', LAUNCH, ids=lambda p: p.name)
def test_launch_file_names_only_what_the_package_installs(path):
    tree = ast.parse(path.read_text())
    executables = set(console_scripts())
    nodes = list(calls(tree, 'Node'))
    assert nodes, 'no Node in the launch file'
    for node in nodes:
        assert ast.literal_eval(keyword(node, 'package')) == 'tskf_ros'
        assert ast.literal_eval(keyword(node, 'executable')) in executables
    yamls = {n.value for n in ast.walk(tree)
             if isinstance(n, ast.Constant) and isinstance(n.value, str)
             and n.value.endswith('.yaml')}
    for name in yamls:
        assert (REPO / 'config' / name).is_file(), name
    declared = {ast.literal_eval(c.args[0]) for c in calls(tree, 'DeclareLaunchArgument')}
    used = {ast.literal_eval(c.args[0]) for c in calls(tree, 'LaunchConfiguration')}
    assert used <= declared, used - declared
    assert USUAL <= declared


def test_the_check_catches_an_unknown_executable(tmp_path):
    bad = tmp_path / 'bad.launch.py'
    bad.write_text("Node(package='tskf_ros', executable='no_such_node')\n")
    tree = ast.parse(bad.read_text())
    (node,) = calls(tree, 'Node')
    assert ast.literal_eval(keyword(node, 'executable')) not in set(console_scripts())


@pytest.mark.skipif(importlib.util.find_spec('launch_ros') is None,
                    reason='launch_ros is not installed (no wheel); the files are checked '
                    'statically above')
@pytest.mark.parametrize('path', LAUNCH, ids=lambda p: p.name)
def test_launch_file_loads(path):
    spec = importlib.util.spec_from_file_location(path.stem.replace('.', '_'), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.generate_launch_description().entities


LIVE_LAYOUTS = {
    # layout -> (namespace, the topics the launch file's nodes publish, relative)
    'foxglove_owc_live.json': ('/', {
        'received_power', 'true_angle', *estimator.OUTPUT_TOPICS.values()}),
    'foxglove_led_live.json': ('/led/', {
        'intensity', 'true_angle', aligner.PAT_STATE_TOPIC, *aligner.OUTPUT_TOPICS.values()}),
    'foxglove_pan_tilt_live.json': ('/pan_tilt/', {
        'intensity', 'true_angle', aligner.PAT_STATE_TOPIC, aligner.OUTPUT_TOPICS['corrected'],
        aligner.COMMAND_TOPIC}),
}


@pytest.mark.parametrize('name', sorted(LIVE_LAYOUTS))
def test_live_foxglove_layouts_plot_only_topics_the_launch_files_publish(name):
    namespace, published = LIVE_LAYOUTS[name]
    layout = json.loads((REPO / 'config' / name).read_text())
    paths = [p['value'] for panel in layout['configById'].values()
             for p in panel.get('paths', [])]
    paths += [panel['topicPath'] for panel in layout['configById'].values()
              if 'topicPath' in panel]
    assert paths
    for path in paths:
        topic = path.split('.')[0]
        assert topic.startswith(namespace), path
        assert topic[len(namespace):] in published, path
