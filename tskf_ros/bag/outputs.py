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

"""The rule every tool's outputs obey: no output is the input bag, a file of it, or holds it."""

import os
from pathlib import Path
from typing import Iterable, Optional, Union

from tskf_ros.bag.bag_errors import resolved
from tskf_ros.bag.writer import BagExistsError

__all__ = ['check_outputs', 'OutputInBagError', 'output_conflict']

PathLike = Union[str, os.PathLike]


class OutputInBagError(BagExistsError):
    """An output path that would overwrite (or delete) a file of an input bag."""


def _bag_root(bag: Path) -> Path:
    """Return the directory of a bag (a bare .mcap file inside a bag directory: that one)."""
    bag = resolved(bag)
    if bag.is_file() and (bag.parent / 'metadata.yaml').is_file():
        return bag.parent
    return bag


def _same_file(a: Path, b: Path) -> bool:
    """Say whether two existing paths are one file (a hard link or a bind mount too)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def output_conflict(output: PathLike, bag: PathLike) -> Optional[str]:
    """
    Return why `output` may not be written for the input `bag`, or None if it may.

    An output may not be the bag (its directory or its .mcap file), a file or directory
    inside the bag's directory, a directory holding the bag (an --overwrite would delete
    it), or, through a hard link, one of the bag's files.  Symlinks are resolved.
    """
    out, root = resolved(output), _bag_root(Path(bag))
    if out == root or out.is_relative_to(root) or root.is_relative_to(out):
        return f'{output}: is (or holds, or is inside) the input bag {bag}; give another output'
    if out.is_file():
        files = [p for p in root.iterdir() if p.is_file()] if root.is_dir() else [root]
        if any(_same_file(out, f) for f in files):
            return f'{output}: is a file of the input bag {bag} (a link); give another output'
    return None


def check_outputs(outputs: Iterable[Optional[PathLike]], bags: Iterable[PathLike]) -> None:
    """Raise OutputInBagError if any output (None: not given) conflicts with any input bag."""
    bags = list(bags)
    for output in outputs:
        if output is None:
            continue
        for bag in bags:
            why = output_conflict(output, bag)
            if why:
                raise OutputInBagError(why)
