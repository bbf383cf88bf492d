"""Write experiment outputs atomically: a file is either whole or absent, never half-written."""

import json
import os
from pathlib import Path
import tempfile
from typing import Any

import numpy as np


def _replace_from_temp(path: Path, write) -> Path:
    path = Path(path)
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


def write_json(path: Path, data: Any) -> Path:
    """Write data as indented JSON (numpy values converted; NaN/inf become null)."""
    text = json.dumps(_jsonable(data), indent=2, allow_nan=False) + '\n'
    return _replace_from_temp(path, lambda f: f.write(text.encode()))


def write_text(path: Path, text: str) -> Path:
    """Write text (UTF-8) through a temporary file renamed into place."""
    return _replace_from_temp(path, lambda f: f.write(text.encode()))


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
