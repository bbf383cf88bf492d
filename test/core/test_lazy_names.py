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

"""A package's names imported on first use: core's, led's and testing's __getattr__."""

import subprocess
import sys
import types

import pytest

from tskf_ros.core.lazy_names import lazy_names


def test_a_name_is_imported_from_its_module_once_and_kept():
    namespace = {}
    getattr_, dir_ = lazy_names('tskf_ros.core', {'TimeScaleLQR': 'lqr'}, namespace)
    from tskf_ros.core.lqr import TimeScaleLQR
    assert getattr_('TimeScaleLQR') is TimeScaleLQR
    assert namespace == {'TimeScaleLQR': TimeScaleLQR}
    assert dir_() == ['TimeScaleLQR']


def test_an_unknown_name_is_an_attribute_error():
    getattr_, _ = lazy_names('tskf_ros.led', {}, {})
    with pytest.raises(AttributeError, match="module 'tskf_ros.led' has no attribute 'nope'"):
        getattr_('nope')


@pytest.mark.parametrize('package', ['tskf_ros.core', 'tskf_ros.led', 'tskf_ros.testing'])
def test_every_name_of_all_is_listed_and_resolves(package):
    module = sys.modules.get(package) or __import__(package, fromlist=['__all__'])
    assert set(module.__all__) <= set(dir(module))
    for name in module.__all__:
        assert not isinstance(getattr(module, name), types.ModuleType), name
    with pytest.raises(AttributeError):
        getattr(module, 'not_a_name')


@pytest.mark.parametrize('package, module', [('tskf_ros.core', 'tskf_ros.core.lqr'),
                                             ('tskf_ros.led', 'tskf_ros.led.scanning_ekf'),
                                             ('tskf_ros.testing', 'tskf_ros.testing.nodes')])
def test_importing_the_package_imports_no_module_of_it(package, module):
    code = (f'import sys, {package}; print({module!r} in sys.modules); '
            f'{package}.__dir__(); print({module!r} in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ['False', 'False']
