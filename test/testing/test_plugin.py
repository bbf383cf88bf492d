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


ISOLATION = ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')

# An unrelated package's test: it records, as JSON into $RECORD, whether the plugin is
# loaded, the environment and which rclpy modules are imported.
UNRELATED_TEST = """
import json
import os
import sys


def test_record(request):
    record = {
        'plugin': getattr(request.config.pluginmanager.get_plugin('tskf_ros'), '__name__', None),
        'environ': {k: v for k, v in os.environ.items()
                    if k not in ('PYTEST_CURRENT_TEST', 'RECORD')},
        'rclpy': sorted(m for m in sys.modules if m.split('.')[0] == 'rclpy'),
    }
    with open(os.environ['RECORD'], 'w') as f:
        json.dump(record, f)
"""


def pytest_elsewhere(tmp_path, *args, env_extra=None):
    """Run pytest in a folder of its own (no conftest or ini of this repository)."""
    (tmp_path / 'pytest.ini').write_text('[pytest]\n')
    env = {k: v for k, v in os.environ.items()
           if k not in ISOLATION and not k.startswith('PYTEST')}
    env.update(env_extra or {})
    return subprocess.run([sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', *args],
                          cwd=tmp_path, env=env, text=True, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, timeout=300)


def test_the_plugin_changes_nothing_in_a_session_that_uses_none_of_its_fixtures(tmp_path):
    import json

    (tmp_path / 'test_unrelated.py').write_text(UNRELATED_TEST)
    records = {}
    for name, extra in (('with', []), ('without', ['-p', 'no:tskf_ros'])):
        record = tmp_path / f'{name}.json'
        proc = pytest_elsewhere(tmp_path, '-q', *extra, 'test_unrelated.py',
                                env_extra={'RECORD': str(record)})
        assert proc.returncode == 0, proc.stdout
        records[name] = json.loads(record.read_text())
    assert records['with']['plugin'] == 'tskf_ros.testing.plugin'   # it was loaded
    assert records['without']['plugin'] is None
    assert records['with']['rclpy'] == [] == records['without']['rclpy']
    assert records['with']['environ'] == records['without']['environ']
    assert not set(ISOLATION) & set(records['with']['environ'])
    # no option or ini value of its own: pytest's help is the same with and without it
    helps = [pytest_elsewhere(tmp_path, '--help', *extra).stdout
             for extra in ([], ['-p', 'no:tskf_ros'])]
    assert helps[0] == helps[1]


# The plugin's fixtures: the ROS environment inside the test, none after it; the
# environment's own ROS_DOMAIN_ID is kept.
FIXTURE_TEST = """
import os

NAMES = ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')
WANT = os.environ.get('WANT_DOMAIN') or str(os.getpid() % 100 + 1)


def test_before():
    assert 'rclpy' not in __import__('sys').modules
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE' not in os.environ


def test_inside(ros_context, ros_environment):
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert os.environ['ROS_DOMAIN_ID'] == WANT
    assert ros_context.get_domain_id() == int(WANT)
    assert ros_environment['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert ('ROS_DOMAIN_ID' in ros_environment) == (not os.environ.get('WANT_DOMAIN'))


def test_after():
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE' not in os.environ
    assert os.environ.get('ROS_DOMAIN_ID') == (os.environ.get('WANT_DOMAIN') or None)
"""


@pytest.mark.parametrize('domain', [None, '42'])
def test_the_fixtures_set_the_ros_environment_for_their_test_only(tmp_path, domain):
    (tmp_path / 'test_fixtures.py').write_text(FIXTURE_TEST)
    extra = {'WANT_DOMAIN': domain, 'ROS_DOMAIN_ID': domain} if domain else {}
    proc = pytest_elsewhere(tmp_path, '-q', 'test_fixtures.py', env_extra=extra)
    assert proc.returncode == 0, proc.stdout
    assert '3 passed' in proc.stdout, proc.stdout


def participants_in_domain(domain: int) -> int:
    """Count the DDS participants of a domain on this machine, from their bound UDP ports."""
    # each participant binds its metatraffic unicast port 7400 + 250 d + 10 + 2 p (the RTPS
    # spec's default port mapping, 9.6.1.1), p its participant id
    first = 7400 + 250 * domain + 10
    ports = set()
    for table in ('/proc/net/udp', '/proc/net/udp6'):
        if os.path.exists(table):
            for line in Path(table).read_text().splitlines()[1:]:
                port = int(line.split()[1].rsplit(':', 1)[1], 16)
                if first <= port < first + 2 * 120 and (port - first) % 2 == 0:
                    ports.add(port)
    return len(ports)


LIFECYCLE_TESTS = 40


@pytest.mark.parametrize('i', range(LIFECYCLE_TESTS))
def test_a_lifecycle_node_in_the_context(ros_context, i):
    from rclpy.lifecycle import LifecycleNode
    LifecycleNode(f'lifecycle_{i}', context=ros_context).destroy_node()


@pytest.mark.skipif(not os.path.exists('/proc/net/udp'), reason='counts sockets in /proc/net')
def test_the_contexts_of_lifecycle_nodes_leave_no_participant_behind():
    # rclpy's LifecycleNode is finalized only by the garbage collector; had the contexts of the
    # tests above kept their participants, a new one would get an id beyond the 32 that
    # localhost discovery tries, and never meet a node of another process
    assert participants_in_domain(int(os.environ['ROS_DOMAIN_ID'])) <= 2
