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

"""Write experiment outputs atomically: a file is either whole or absent, never half-written."""

import json
import os
from pathlib import Path
import tempfile
from typing import Any, Optional, Sequence

import numpy as np


def unwritable(path: Path) -> Optional[str]:
    """
    Return why `path` cannot be written as an output (before a long run), or None.

    By trying: a folder, or something there that is not a plain file (a FIFO, a device),
    is refused; the nearest existing folder above it must take a temporary file of the
    name this module writes through (a read-only or virtual file system, a name too
    long, no permission: say so).
    """
    path = Path(path)
    try:
        if path.is_dir():
            return f'{path} is a folder'
        if path.exists() and not path.is_file():
            return f'{path} is not a plain file'
        parent = path.parent
        while not parent.exists():
            parent = parent.parent
        if not parent.is_dir():
            return f'{parent} is not a folder'
        fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.part', dir=parent)
    except OSError as exc:
        return f'cannot write in {path.parent}: {exc.strerror or exc}'
    os.close(fd)
    os.unlink(tmp)
    return None


def _replace_from_temp(path: Path, write) -> Path:
    path = Path(path)
    if path.exists() and not path.is_file() and not path.is_dir():
        # a FIFO or a device is not replaced by a plain file
        raise OSError(f'{path} is not a plain file')
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.part', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            write(f)
        os.chmod(tmp, 0o644)          # mkstemp makes 0600; outputs are for reading
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if np.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def json_bytes(data: Any) -> bytes:
    """Return data as indented JSON (numpy values converted; NaN/inf become null)."""
    return (json.dumps(_jsonable(data), indent=2, allow_nan=False) + '\n').encode()


def write_json(path: Path, data: Any) -> Path:
    """Write data as indented JSON (numpy values converted; NaN/inf become null)."""
    text = json_bytes(data)
    return _replace_from_temp(path, lambda f: f.write(text))


def write_text(path: Path, text: str) -> Path:
    """Write text (UTF-8) through a temporary file renamed into place."""
    return _replace_from_temp(path, lambda f: f.write(text.encode()))


def write_all(files: Sequence[tuple[Path, bytes]]) -> None:
    """
    Write several files all or none: each staged as a temporary file, then renamed.

    A target that is a directory, or whose directory cannot be made or written, fails
    before any target is replaced.  If anything fails (Ctrl-C too) after some targets
    were replaced, those are put back as they were (a new one removed, an old one restored
    from a hard link kept until the end); a directory made for a target is removed again.
    """
    staged: list[tuple[str, Path]] = []
    made: list[Path] = []
    done: list[tuple[Path, Optional[str]]] = []     # replaced targets, their backups
    try:
        for path, data in files:
            path = Path(path)
            if path.is_dir():
                raise IsADirectoryError(21, 'Is a directory', str(path))
            missing = [p for p in [path.parent, *path.parent.parents] if not p.exists()]
            path.parent.mkdir(parents=True, exist_ok=True)
            made += reversed(missing)
            fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.part', dir=path.parent)
            staged.append((tmp, path))
            with os.fdopen(fd, 'wb') as f:
                f.write(data)
            os.chmod(tmp, 0o644)
        for tmp, path in staged:
            backup = None
            if path.exists():
                backup = f'{tmp}.old'
                os.link(path, backup)
            done.append((path, backup))
            os.replace(tmp, path)
    except BaseException:
        for path, backup in reversed(done):
            if backup is not None:
                os.replace(backup, path)
            else:
                path.unlink(missing_ok=True)
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        for d in reversed(made):
            try:
                d.rmdir()
            except OSError:
                pass
        raise
    for _, backup in done:
        if backup is not None:
            Path(backup).unlink(missing_ok=True)


def save_figure(fig, path: Path, dpi: int = 110) -> Path:
    """Save a matplotlib figure as PNG through a temporary file, then close it."""
    import matplotlib.pyplot as plt
    try:
        return _replace_from_temp(
            path, lambda f: fig.savefig(f, format='png', dpi=dpi, bbox_inches='tight'))
    finally:
        plt.close(fig)


def save_results(out: Path, name: str, fig, data: Any) -> None:
    """Write <name>.png and <name>.json into out and say so."""
    save_figure(fig, Path(out) / f'{name}.png')
    write_json(Path(out) / f'{name}.json', data)
    print(f'wrote {Path(out) / (name + ".png")} and {Path(out) / (name + ".json")}')
