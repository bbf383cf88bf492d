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

"""A package's names imported from their modules on first use (PEP 562)."""

import importlib
from typing import Any, Callable


def lazy_names(package: str, sources: dict[str, str],
               namespace: dict[str, Any]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """
    Return a package's module-level __getattr__ and __dir__ for the names of sources.

    sources maps each name to the module of package it comes from; the first use of a name
    imports that module and keeps the name in namespace (the package's globals()), so that
    later uses do not come back here.  A package imports only what its callers use.
    """
    def __getattr__(name: str) -> Any:
        """Import a name of __all__ from its module on first use."""
        if name not in sources:
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        value = getattr(importlib.import_module(f'{package}.{sources[name]}'), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        """List the module's names, those not imported yet included."""
        return sorted(set(namespace) | set(sources))
    return __getattr__, __dir__
