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

"""The sweep's tasks: bags x settings, the key each row is resumed by, one evaluation."""

from dataclasses import dataclass
import glob
import hashlib
import itertools
import json
from pathlib import Path
import time
from typing import Iterable, Optional, Protocol, Union

import numpy as np

from tskf_ros.experiments.bag_analysis import evaluate_bag, read_stream
from tskf_ros.experiments.fit_noise import fit_events
from tskf_ros.messages.estimator_interface import load_config, NodeConfig

import yaml

FIT_COLUMNS = ['fit_Q', 'fit_R', 'fit_Q_stderr', 'fit_R_stderr', 'fit_log_likelihood',
               'fit_nis_mean', 'fit_error']
# parameters a --set may not change: they do not affect an offline evaluation
NOT_SETTABLE = ('queue_depth', 'diagnostic_updater.period', 'status_period', 'frame_id',
                'measurement_type')
# one value of a --set: typed as the parameter's default (a matrix: a list of floats)
SettingValue = Union[bool, int, float, str, list]


@dataclass(frozen=True)
class Task:
    """One bag x one setting, with the config built from it."""

    key: str
    bag: str
    setting: dict
    config: NodeConfig
    topic: Optional[str] = None
    fit: bool = False


def find_bags(patterns: Iterable[str]) -> list:
    """
    Resolve bag arguments into a sorted list of bags.

    An argument is a bag (a directory with metadata.yaml, or a .mcap file), a directory
    holding bags (searched recursively), or a glob pattern ('**' recursive).
    """
    found: set = set()

    def is_bag(p: Path) -> bool:
        return (p.is_dir() and (p / 'metadata.yaml').is_file()) or (
            p.is_file() and p.suffix == '.mcap' and not (p.parent / 'metadata.yaml').is_file())

    for pattern in patterns:
        matches = [Path(p) for p in sorted(glob.glob(pattern, recursive=True))] or [
            Path(pattern)]
        for p in matches:
            if is_bag(p):
                found.add(str(p))
            elif p.is_dir():
                found.update(str(m.parent) for m in p.rglob('metadata.yaml'))
                found.update(str(m) for m in p.rglob('*.mcap')
                             if not (m.parent / 'metadata.yaml').is_file())
    return unique_bags(found)


def unique_bags(bags: Iterable[str]) -> list:
    """
    Return the bags sorted, one spelling per bag: its real path if given, else the first.

    A bag given by its path and through a symlink (or twice through links) is one bag
    (its resolved path): evaluated once, one row.
    """
    by_real: dict = {}
    for bag in sorted(bags):
        real = str(Path(bag).resolve())
        if real not in by_real or bag == real:
            by_real[real] = bag
    return sorted(by_real.values())


def parse_setting(text: str, defaults: dict) -> tuple[str, list]:
    """
    Parse NAME=v1,v2,...: each value typed as the parameter's default.

    A matrix parameter takes each value as space-separated numbers (R=100 or 'R=1 0 0 1').
    """
    if '=' not in text:
        raise ValueError(f'--set {text!r}: expected NAME=value1,value2,...')
    name, _, values = text.partition('=')
    name = name.strip()
    if name not in defaults or name in NOT_SETTABLE:
        raise ValueError(f'--set {name}: not a parameter of the estimator a sweep can set')
    default = defaults[name]
    out = []
    for raw in values.split(','):
        raw = raw.strip()
        if not raw:
            raise ValueError(f'--set {text!r}: an empty value')
        if isinstance(default, (list, tuple)) and all(isinstance(v, str) for v in default) \
                and default:
            value = raw.split()                     # a list of names (state_names)
        elif isinstance(default, (list, tuple)):
            try:
                value = [float(v) for v in raw.split()]
            except ValueError:
                raise ValueError(f'--set {name}: {raw!r} is not a list of numbers') from None
        elif isinstance(default, bool):
            value = yaml.safe_load(raw)
            if not isinstance(value, bool):
                raise ValueError(f'--set {name}: {raw!r} is not true or false')
        elif isinstance(default, float):
            try:
                value = float(raw)
            except ValueError:
                raise ValueError(f'--set {name}: {raw!r} is not a number') from None
        elif isinstance(default, int):
            try:
                number = float(raw)
            except ValueError:
                raise ValueError(f'--set {name}: {raw!r} is not an integer') from None
            if not number.is_integer():     # 1e3 is one (1000), 2.5 and inf are not
                raise ValueError(f'--set {name}: {raw!r} is not an integer')
            value = int(number)
        else:
            value = raw
        out.append(value)
    return name, out


def settings_product(sets: list) -> list:
    """Return every combination of the --set values as a list of {name: value} dicts."""
    names = [n for n, _ in sets]
    if len(set(names)) != len(names):
        raise ValueError('a parameter is given to --set twice')
    return [dict(zip(names, combo)) for combo in itertools.product(*[v for _, v in sets])]


def setting_text(value: SettingValue) -> str:
    """Return a setting's value as the CSV shows it."""
    if isinstance(value, list):
        return ' '.join(v if isinstance(v, str) else repr(float(v)) for v in value)
    return str(value)


def bag_signature(bag: str) -> list:
    """Return (name, size, mtime_ns) of every file of a bag: what the resume key covers."""
    p = Path(bag)
    files = sorted(p.rglob('*')) if p.is_dir() else [p]
    out = []
    for f in files:
        if f.is_file():
            st = f.stat()
            out.append([str(f.relative_to(p) if p.is_dir() else f.name), st.st_size,
                        st.st_mtime_ns])
    return out


def task_key(bag: str, params_text: str, setting: dict, topic: Optional[str],
             fit: bool) -> str:
    """Return the row key: a hash of the bag's path and files, the parameters and setting."""
    blob = json.dumps([str(Path(bag).resolve()), bag_signature(bag), params_text,
                       {k: setting_text(v) for k, v in setting.items()}, topic, fit],
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def one_line(exc: BaseException) -> str:
    """Return an exception as one line: its type and message."""
    text = ' '.join(str(exc).split()) or repr(exc)
    return f'{type(exc).__name__}: {text}'


class Progress(Protocol):
    """What a task tells while it runs (sweep_progress.TaskProgress)."""

    def messages(self, n: int) -> None: ...

    def phase(self, text: str) -> None: ...

    def fit_progress(self, evaluations: int, log_likelihood: float) -> None: ...

    def flush(self) -> None: ...


def run_task(task: Task, progress: Optional[Progress] = None) -> dict:
    """
    Evaluate one bag x setting (on a worker); never raises: errors go into the row.

    progress: told the messages read as they are read, and the fit's phase.
    """
    t0 = time.perf_counter()
    row = {'key': task.key, 'bag': task.bag, 'error': ''}
    row.update({name: setting_text(v) for name, v in task.setting.items()})
    tick = progress.messages if progress is not None else None
    try:
        row.update(evaluate_bag(task.bag, task.config, topic=task.topic, tick=tick))
        if row.get('damage'):
            row['error'] = f'damaged: {row["damage"]}'
    except Exception as exc:  # noqa: B902 - a bad bag must not stop the sweep
        row['error'] = one_line(exc)
    if task.fit and not row['error']:
        row.update(fit_columns(task, progress))
    row['seconds'] = time.perf_counter() - t0
    if progress is not None:
        progress.flush()
    return row


def fit_columns(task: Task, progress: Optional[Progress] = None) -> dict:
    """Run fit_noise's fit on the bag with the task's config; return the fit_* columns."""
    out = {c: '' for c in FIT_COLUMNS}
    try:
        cfg = task.config.session
        if progress is not None:
            progress.phase('reading for the fit')
        stream = read_stream(task.bag, cfg, topic=task.topic, truth=False,
                             tick=progress.messages if progress is not None else None)
        sf, report = fit_events(cfg, stream.events,
                                progress=progress.fit_progress if progress is not None
                                else None)
        for name in ('Q', 'R', 'Q_stderr', 'R_stderr'):
            out[f'fit_{name}'] = json.dumps(np.asarray(report[name]).tolist())
        out['fit_log_likelihood'] = report['log_likelihood']
        out['fit_nis_mean'] = report['nis']['mean']
    except Exception as exc:  # noqa: B902 - a failed fit is reported in its row
        out['fit_error'] = one_line(exc)
    return out


def build_tasks(bags: list, params_file: Optional[Path], sets: list, *,
                topic: Optional[str] = None, fit: bool = False) -> list:
    """Return one Task per bag x setting; raise ParamsError for a setting the node refuses."""
    params_text = Path(params_file).read_text() if params_file else ''
    tasks: dict = {}
    for setting in settings_product(sets):
        config = load_config(params_file, setting)
        for bag in bags:
            key = task_key(bag, params_text, setting, topic, fit)
            # one key, one task: the same bag twice (a symlink) is evaluated once
            tasks.setdefault(key, Task(key, bag, setting, config, topic, fit))
    return list(tasks.values())
