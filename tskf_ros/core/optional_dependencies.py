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
The optional libraries of tskf_ros: which feature needs which, and how to install them.

The estimator, the simulators, the alignment node, the launch files, bag record/play and
the offline replay need only the system packages rosdep installs (numpy, scipy, PyYAML,
matplotlib, tqdm), numba and the bag libraries (mcap, rosbags).  The features below need
more; their libraries are imported only when the feature is used, and a missing one ends
the tool with one line naming what to install (MissingDependency, which the console entry
prints).  setup.py's extras_require and package.xml's comments follow this table
(test/package/test_package_xml.py checks both).
"""

from dataclasses import dataclass
import importlib
from types import ModuleType
from typing import Optional

__all__ = ['EXIT_MISSING_DEPENDENCY', 'Extra', 'EXTRAS', 'extra_of', 'MissingDependency',
           'require']

# exit status of a tool whose optional library is not installed (as a usage error)
EXIT_MISSING_DEPENDENCY = 2


@dataclass(frozen=True)
class Extra:
    """One optional tier: a setup.py extra, the features it serves, how to install it."""

    name: str                       # `pip install 'tskf_ros[<name>]'`
    features: str                   # what needs it, for the message and the docs
    modules: tuple                  # the top-level modules it provides
    requirements: tuple             # its setup.py extras_require entries (pip names)
    rosdep_keys: tuple              # the keys of config/rosdep/tskf_ros.yaml or rosdistro


EXTRAS = {extra.name: extra for extra in (
    Extra('analysis', 'sweep --workers/--scheduler (a Dask cluster)',
          ('dask', 'distributed'), ('dask[distributed]',),
          ('python3-dask-pip', 'python3-distributed-pip')),
    Extra('foxglove', 'foxglove_bridge (the Foxglove live view)',
          ('foxglove',), ('foxglove-sdk',), ('python3-foxglove-sdk-pip',)),
    Extra('visa', 'power_meter_driver (a VISA power meter)',
          ('pyvisa', 'pyvisa_py', 'usb', 'libusb_package'),
          ('pyvisa', 'pyvisa-py', 'pyusb', 'libusb-package'),
          ('python3-pyvisa-pip', 'python3-pyvisa-py-pip', 'python3-usb',
           'python3-libusb-package-pip')),
    Extra('threads', 'the nodes limiting their BLAS to one thread (without it: BLAS default)',
          ('threadpoolctl',), ('threadpoolctl',), ('python3-threadpoolctl-pip',)),
)}


class MissingDependency(ImportError):
    """An optional library that a feature needs is not installed: one line saying what to do."""


def extra_of(module: Optional[str]) -> Optional[Extra]:
    """Return the extra that provides a (dotted) module name, or None."""
    top = (module or '').split('.')[0]
    return next((e for e in EXTRAS.values() if top in e.modules), None)


def message(extra: Extra, module: str, feature: str = '') -> str:
    """Return the one line that says a module of an extra is not installed (for a feature)."""
    top = module.split('.')[0]
    what = f'{feature} needs {top}, which is not installed' if feature else \
        f'{top} is not installed'
    return (f"{what}: pip install {' '.join(map(repr, extra.requirements))} (the extra "
            f'tskf_ros[{extra.name}]; rosdep keys {" ".join(extra.rosdep_keys)})')


def missing(exc: ModuleNotFoundError, feature: str = '') -> Optional[MissingDependency]:
    """Return the MissingDependency an import error of an optional library means, or None."""
    extra = extra_of(exc.name)
    if extra is None or exc.name is None:
        return None
    return MissingDependency(message(extra, exc.name, feature))


def require(module: str, feature: str = '') -> ModuleType:
    """Import an optional module; raise MissingDependency (one line) if it is not installed."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        error = missing(exc, feature)
        if error is None:
            raise
        raise error from None
