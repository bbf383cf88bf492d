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

import compileall
from glob import glob
import os
import subprocess
import sys

from setuptools import find_packages
from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.develop import develop
from setuptools.command.install_scripts import install_scripts

package_name = 'tskf_ros'


def _files(pattern):
    """Return the files (not directories) matching a glob pattern, sorted."""
    return sorted(path for path in glob(pattern, recursive=True) if os.path.isfile(path))


def _tree(top):
    """Map every file below top to a share/<package>/<relative dir> data_files entry."""
    entries = {}
    for path in _files(os.path.join(top, '**', '*')):
        target = os.path.join('share', package_name, os.path.dirname(path))
        entries.setdefault(target, []).append(path)
    return sorted(entries.items())


def _compile_kernels(root, output, numba_cache=None):
    """
    Compile the nodes' kernels ahead of time into output (python -m tskf_ros.core.aot).

    root holds the tskf_ros being installed; its aot module says in one line what it did,
    and without numba or a C compiler the package builds all the same (doc/installation.md).
    """
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [os.path.abspath(root)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    if numba_cache:
        env.setdefault('NUMBA_CACHE_DIR', os.path.abspath(numba_cache))
    result = subprocess.run(
        [sys.executable, '-m', 'tskf_ros.core.aot', '--if-possible', '--output', output],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = (result.stdout.strip().splitlines() or [f'exit status {result.returncode}'])[-1]
    if result.returncode:       # it did not even start (numpy missing, say)
        line = f'the ahead-of-time build failed ({line}): the nodes will compile at start'
    built = result.returncode == 0 and line.startswith("the nodes' kernels compiled")
    print(f'tskf_ros: {line}', file=sys.stdout if built else sys.stderr)


def _byte_compile(package_dir):
    """
    Write the bytecode (__pycache__/*.pyc) of every module below package_dir.

    Python writes it on a module's first import, unless the tree is read-only or
    PYTHONDONTWRITEBYTECODE is set (distutils' install_lib skips it then too): a node would
    compile its about 120 modules from source at every start (doc/benchmarks.md).
    """
    compileall.compile_dir(package_dir, quiet=1)


def _direct_scripts(directory, entry_points):
    """
    Rewrite the console scripts in directory to import their function directly.

    setuptools' scripts (`setup.py install`, `develop`: colcon's build, ./run's editable
    install) look their function up through importlib.metadata at every start, about
    0.1 s of a loaded machine; these import it as pip's scripts do.  A file that is not
    there or has no Python shebang is left as it is.
    """
    for spec in entry_points.get('console_scripts', []):
        name, target = (part.strip() for part in spec.split('='))
        module, function = target.split(':')
        path = os.path.join(directory, name)
        if not os.path.isfile(path):
            continue
        with open(path) as f:
            shebang = f.readline().rstrip('\n')
        if not (shebang.startswith('#!') and 'python' in shebang):
            continue
        with open(path, 'w') as f:
            f.write(f'{shebang}\n# {name}: runs {target} (setup.py writes it)\nimport sys\n\n'
                    f'from {module} import {function}\n\n'
                    f"if __name__ == '__main__':\n    sys.exit({function}())\n")


class BuildWithKernels(build_py):
    """build_py, then the nodes' kernels into the built package's core/__pycache__."""

    def run(self):
        super().run()
        if not getattr(self, 'editable_mode', False):   # else the sources are used in place
            _compile_kernels(
                self.build_lib, os.path.join(self.build_lib, package_name, 'core', '__pycache__'),
                numba_cache=os.path.join(os.path.dirname(self.build_lib), 'numba_cache'))
            _byte_compile(os.path.join(self.build_lib, package_name))

    def get_outputs(self, include_bytecode=1):
        """Return build_py's files and the kernels' module (install --record lists them)."""
        return super().get_outputs(include_bytecode) + _files(
            os.path.join(self.build_lib, package_name, 'core', '__pycache__', 'tskf_kernels_*'))


class InstallScripts(install_scripts):
    """install_scripts (colcon build, setup.py install), the console scripts importing directly."""

    def run(self):
        super().run()
        _direct_scripts(self.install_dir, self.distribution.entry_points)


class DevelopWithKernels(develop):
    """develop (colcon build --symlink-install), then the kernels beside the sources."""

    def run(self):
        super().run()
        if not self.uninstall:
            core = os.path.realpath(os.path.join(package_name, 'core'))
            _compile_kernels(os.path.dirname(os.path.dirname(core)),
                             os.path.join(core, '__pycache__'))
            _byte_compile(os.path.dirname(core))
            _direct_scripts(self.script_dir, self.distribution.entry_points)


setup(
    name=package_name,
    cmdclass={'build_py': BuildWithKernels, 'develop': DevelopWithKernels,
              'install_scripts': InstallScripts},
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', _files('config/*.yaml') + _files('config/*.json')),
        ('share/' + package_name + '/config/rosdep', _files('config/rosdep/*.yaml')),
        ('share/' + package_name + '/config/schema', _files('config/schema/*.yaml')),
        ('share/' + package_name + '/launch', _files('launch/*.launch.py')),
        ('share/' + package_name + '/urdf', _files('urdf/*.urdf')),
    ] + _tree('bags'),
    # Tier 1 (the nodes, launch files, bags, experiments) comes from package.xml through
    # rosdep (system packages on Ubuntu 24.04, plus mcap and rosbags from pip), or from
    # requirements.txt in ./run's venv. The optional features are extras, imported only
    # when used (tskf_ros/core/optional_dependencies.py, the same table; doc/installation.md):
    # pip install './src/tskf_ros[analysis,foxglove,visa,threads]'
    install_requires=['setuptools'],
    extras_require={
        'analysis': ['dask[distributed]'],      # sweep --workers/--scheduler
        'foxglove': ['foxglove-sdk'],           # foxglove_bridge
        'visa': ['pyvisa', 'pyvisa-py', 'pyusb', 'libusb-package'],   # power_meter_driver
        'threads': ['threadpoolctl'],           # the nodes' BLAS on one thread
    },
    zip_safe=True,
    maintainer='tskf_ros maintainers',
    maintainer_email='tskf-ros@example.org',
    keywords=['ROS'],
    classifiers=[
        'Intended Audience :: Developers',
        'License :: OSI Approved :: Apache Software License',
        'Programming Language :: Python',
        'Topic :: Software Development',
    ],
    description='Kalman filtering on time scales for intermittent optical wireless links (ROS 2).',
    license='Apache-2.0',
    tests_require=['pytest'],
    # One executable per line; test/package/test_colcon_build.py checks each of them.
    entry_points={
        # each through a wrapper that imports the tool inside its Ctrl-C handling
        'console_scripts': [
            'reproduce = tskf_ros.tools.console:reproduce',
            'power_meter_simulator = tskf_ros.tools.console:power_meter_simulator',
            'timescale_estimator = tskf_ros.tools.console:timescale_estimator',
            'record = tskf_ros.tools.console:record',
            'play = tskf_ros.tools.console:play',
            'replay_offline = tskf_ros.tools.console:replay_offline',
            'reindex = tskf_ros.tools.console:reindex',
            'plot_bag = tskf_ros.tools.console:plot_bag',
            'make_sample_bags = tskf_ros.tools.console:make_sample_bags',
            'led_link_simulator = tskf_ros.tools.console:led_link_simulator',
            'alignment = tskf_ros.tools.console:alignment',
            'power_meter_driver = tskf_ros.tools.console:power_meter_driver',
            'fit_noise = tskf_ros.tools.console:fit_noise',
            'sweep = tskf_ros.tools.console:sweep',
            'foxglove_bridge = tskf_ros.tools.console:foxglove_bridge',
        ],
        # the fixtures of tskf_ros.testing, for any pytest run where the package is installed
        'pytest11': ['tskf_ros = tskf_ros.testing.plugin'],
    },
)
