"""tskf_ros.testing: the pytest plugin, found through its entry point, and its helpers."""

import os
from pathlib import Path
import shutil
import subprocess
import sys

from entry_points import console_scripts
import pytest
from rclpy.parameter import Parameter
from tskf_ros.testing import node_class, NODES, spin_until
from tskf_ros.testing.nodes import overrides

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / 'doc' / 'examples' / 'test_with_tskf_ros.py'


def test_every_node_executable_is_in_nodes():
    node_modules = {path.stem for path in (REPO / 'tskf_ros' / 'nodes').glob('*.py')
                    if 'def main(' in path.read_text()}
    assert set(NODES) == node_modules
    assert set(NODES) <= set(console_scripts())
    for name in NODES:
        assert node_class(name).__module__ == f'tskf_ros.nodes.{name}'


def test_an_unknown_node_name_is_refused_with_the_choices():
    with pytest.raises(ValueError, match='not a node of tskf_ros.*timescale_estimator'):
        node_class('nope')


def test_overrides_read_the_nodes_sections_and_the_given_values_win(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    a: 1\n    b: 1\n'
                    '/**/est:\n  ros__parameters:\n    b: 2\n    nested: {c: 3.5}\n'
                    '/other:\n  ros__parameters:\n    a: 9\n')
    got = {p.name: p.value for p in overrides({'a': 7}, path, 'est')}
    assert got == {'a': 7, 'b': 2, 'nested.c': 3.5}
    listed = overrides([Parameter('b', value=5)], path, 'other')
    assert {p.name: p.value for p in listed} == {'a': 9, 'b': 5}


def test_spin_until_says_what_never_happened(ros_executor):
    with pytest.raises(TimeoutError, match='timed out after 0.1 s waiting for the answer'):
        spin_until(ros_executor, lambda: False, timeout=0.1, what='the answer')


def test_start_node_starts_a_node_of_the_package_with_overrides(start_node):
    node = start_node('power_meter_simulator', parameters={'rate': 7.0, 'seed': 3})
    assert node.get_parameter('rate').value == 7.0
    assert node.get_parameter('seed').value == 3


@pytest.mark.slow
def test_the_documented_example_runs_with_only_the_installed_plugin(tmp_path):
    # a directory of its own: no conftest of this repository applies, only the plugin
    shutil.copy(EXAMPLE, tmp_path / EXAMPLE.name)
    env = {k: v for k, v in os.environ.items() if k != 'ROS_DOMAIN_ID'}
    proc = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                           EXAMPLE.name], cwd=tmp_path, env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=300)
    assert proc.returncode == 0, proc.stdout
    assert '2 passed' in proc.stdout
