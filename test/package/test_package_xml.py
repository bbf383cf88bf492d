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
package.xml declares every import of the package and its tests, by keys rosdep resolves.

The imports are read from the package's modules, its launch files and its tests. Every key
is a rosdep key of ros/rosdistro (snapshot: test/data/rosdistro_keys.yaml), a ROS 2 Jazzy
package of its distribution.yaml (same snapshot), or a pip rule of the rosdep file the
package ships (config/rosdep/tskf_ros.yaml).
"""

import ast
from importlib import metadata
import os
from pathlib import Path
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest
from tskf_ros.core.optional_dependencies import extra_of, EXTRAS
import yaml

REPO = Path(__file__).resolve().parents[2]
SNAPSHOT = REPO / 'test' / 'data' / 'rosdistro_keys.yaml'
SHIPPED = REPO / 'config' / 'rosdep' / 'tskf_ros.yaml'
ROSDEP_FILES = ('rosdep/base.yaml', 'rosdep/python.yaml')
DISTRIBUTION = 'jazzy/distribution.yaml'
# top-level import -> the package.xml key that provides it (ROS packages: their own name)
KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'matplotlib': 'python3-matplotlib',
    # zstandard: a requirement of mcap's own (mcap reads zstd chunks with it)
    'yaml': 'python3-yaml', 'zstandard': 'python3-mcap-pip',
    'mcap': 'python3-mcap-pip', 'rosbags': 'python3-rosbags-pip',
    'pytest': 'python3-pytest', 'hypothesis': 'python3-hypothesis',
    'mcap_ros2': 'mcap-ros2-support',
    'pyvisa': 'python3-pyvisa-pip', 'pyvisa_sim': 'python3-pyvisa-sim-pip',
    'dask': 'python3-dask-pip', 'distributed': 'python3-distributed-pip', 'tqdm': 'python3-tqdm',
    'numba': 'python3-numba-pip', 'mypy': 'python3-mypy', 'filterpy': 'python3-filterpy-pip',
    'pykalman': 'python3-pykalman-pip',
    'foxglove': 'python3-foxglove-sdk-pip', 'websockets': 'python3-websockets',
    'threadpoolctl': 'python3-threadpoolctl-pip',
}
RUN = ('exec_depend', 'depend')
TEST = RUN + ('test_depend',)
# the tier-1 keys that are pip-only: the bag libraries, which no distribution packages, and
# numba, which Ubuntu 24.04 does not package
PIP_ONLY_RUNTIME = {'python3-rosbags-pip', 'python3-mcap-pip', 'python3-numba-pip'}
# rosdistro keys that name an apt package Ubuntu 24.04 does not have (noble's Packages
# files, cited in ubuntu-24.04-constraints.txt): the shipped file's pip key replaces each
NOT_ON_NOBLE = {'python3-numba'}


def declared(kinds):
    root = ET.parse(REPO / 'package.xml').getroot()
    return {e.text.strip() for kind in kinds for e in root.iter(kind)}


def top_level_imports(paths):
    found = {}
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module]
            for name in names:
                top = name.split('.')[0]
                local = (any((REPO / 'test').rglob(f'{top}.py'))
                         or (REPO / 'test' / top / '__init__.py').is_file()
                         or (REPO / 'bench' / f'{top}.py').is_file())
                if top not in sys.stdlib_module_names and top != 'tskf_ros' and not local:
                    found.setdefault(top, path.name)
    return found


def missing(imports, kinds):
    have = declared(kinds)
    return {top: where for top, where in imports.items() if KEYS.get(top, top) not in have}


# imported by pytest only (the pytest11 entry point), so pytest is there whenever it is: a
# test_depend of this package, and of every package whose tests use the plugin
PYTEST_PLUGIN = REPO / 'tskf_ros' / 'testing' / 'plugin.py'


def test_every_runtime_import_is_an_exec_depend_or_of_an_optional_tier():
    code = sorted(path for path in (REPO / 'tskf_ros').rglob('*.py') if path != PYTEST_PLUGIN)
    code += sorted((REPO / 'launch').glob('*.py'))
    imports = top_level_imports(code)
    assert {'rclpy', 'rcl_interfaces', 'numpy', 'launch_ros', 'mcap', 'dask'} <= set(imports)
    required = {top: where for top, where in imports.items() if extra_of(top) is None}
    assert missing(required, RUN) == {}
    # an optional library is no exec_depend: its extra's keys are test_depends (its tests)
    optional = {KEYS[top] for top in imports if extra_of(top)}
    assert optional & declared(RUN) == set()
    assert optional <= declared(('test_depend',))


def test_the_optional_tiers_are_test_depends_only_and_resolve():
    keys = {key for extra in EXTRAS.values() for key in extra.rosdep_keys}
    snap, shipped = snapshot(), shipped_rules()
    known = {key for name in ROSDEP_FILES for key in snap[name]} | set(shipped)
    assert keys <= known
    assert keys & declared(RUN) == set()
    assert keys <= declared(('test_depend',))
    comment = (REPO / 'package.xml').read_text()
    assert all(key in comment for key in keys)   # the tier table in package.xml's comment


def test_tier_one_has_no_pip_key_but_the_bag_libraries_and_numba():
    run = declared(RUN)
    assert {key for key in run if key.endswith('-pip')} == PIP_ONLY_RUNTIME
    assert 'ros2launch' in run


def test_every_test_import_is_declared():
    imports = top_level_imports(sorted((REPO / 'test').rglob('*.py')))
    assert missing(imports, TEST) == {}


def test_the_check_catches_an_undeclared_import(tmp_path):
    code = tmp_path / 'x.py'
    code.write_text('import pandas\nfrom nav_msgs.msg import Odometry\nimport json\n')
    assert set(missing(top_level_imports([code]), RUN)) == {'pandas', 'nav_msgs'}


def package_keys() -> dict:
    """Return {key: the tag it is declared in} for every dependency of package.xml."""
    root = ET.parse(REPO / 'package.xml').getroot()
    return {e.text.strip(): e.tag for e in root if e.tag.endswith('depend')}


def snapshot() -> dict:
    return yaml.safe_load(SNAPSHOT.read_text())


def shipped_rules() -> dict:
    return yaml.safe_load(SHIPPED.read_text())


def test_every_key_resolves_in_rosdistro_or_the_shipped_rules():
    snap, shipped = snapshot(), shipped_rules()
    known = {key for name in ROSDEP_FILES for key in snap[name]} | set(snap[DISTRIBUTION])
    unresolved = set(package_keys()) - known - set(shipped)
    assert unresolved == set()
    # no key of the shipped file shadows one of rosdistro's, and neither lists a key unused
    assert known & set(shipped) == set()
    assert set(shipped) <= set(package_keys())


def test_the_shipped_rules_are_pip_rules_of_installed_distributions():
    for key, rules in shipped_rules().items():
        assert re.fullmatch(r'python3-[a-z0-9-]+-pip', key), key
        assert {'debian', 'ubuntu'} <= set(rules), key
        for os_name, rule in rules.items():
            assert list(rule) == ['pip'] and list(rule['pip']) == ['packages'], (key, os_name)
            packages = rule['pip']['packages']
            assert packages == rules['ubuntu']['pip']['packages'], (key, os_name)
        for name in rules['ubuntu']['pip']['packages']:
            assert re.fullmatch(r'[A-Za-z0-9][A-Za-z0-9._-]*', name), (key, name)
            metadata.distribution(name)   # raises PackageNotFoundError if not installed here


def test_the_rosdep_file_is_installed_and_documented():
    setup = (REPO / 'setup.py').read_text()
    assert "_files('config/rosdep/*.yaml')" in setup
    doc = (REPO / 'doc' / 'design' / 'rosdep.md').read_text()
    assert '/etc/ros/rosdep/sources.list.d/50-tskf-ros.list' in doc
    assert 'config/rosdep/tskf_ros.yaml' in doc and 'rosdep update' in doc


def test_package_xml_names_its_maintainer_author_and_urls():
    root = ET.parse(REPO / 'package.xml').getroot()
    maintainer = root.find('maintainer')
    assert re.fullmatch(r'[\w.+-]+@[\w-]+(\.[\w-]+)+', maintainer.get('email'))
    assert root.find('author').text.strip()
    # the maintainer and URLs are placeholders until a release: package.xml says so
    assert 'PLACEHOLDERS' in (REPO / 'package.xml').read_text()
    assert (REPO / 'CHANGELOG.rst').is_file()
    urls = {url.get('type'): url.text for url in root.iter('url')}
    assert set(urls) == {'website', 'repository'}
    assert all(url.startswith('https://') for url in urls.values())


def _rosdistro_file(where: Path, name: str) -> str:
    """Return a file of a rosdistro work tree, or of a (bare) git clone's HEAD."""
    if (where / name).is_file():
        return (where / name).read_text()
    return subprocess.run(['git', '-C', str(where), 'show', f'HEAD:{name}'], check=True,
                          capture_output=True, text=True).stdout


@pytest.mark.skipif(not os.environ.get('TSKF_ROSDISTRO'),
                    reason='TSKF_ROSDISTRO (a ros/rosdistro checkout) is not set')
def test_the_snapshot_matches_rosdistro():
    where, snap = Path(os.environ['TSKF_ROSDISTRO']), snapshot()
    defined = set()
    for name in ROSDEP_FILES:
        keys = set(yaml.safe_load(_rosdistro_file(where, name)))
        assert set(snap[name]) <= keys, name
        defined |= keys
    released = {}
    for repo, entry in yaml.safe_load(
            _rosdistro_file(where, DISTRIBUTION))['repositories'].items():
        for package in (entry.get('release') or {}).get('packages', [repo]):
            released[package] = repo
    assert {p: released.get(p) for p in snap[DISTRIBUTION]} == snap[DISTRIBUTION]
    # a shipped key (or its name without -pip) that rosdistro has now should be used instead
    shipped = set(shipped_rules())
    assert shipped & (defined | set(released)) == set()
    assert {key[:-len('-pip')] for key in shipped} & defined == NOT_ON_NOBLE
