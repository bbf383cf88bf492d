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

"""Parameter files: the reader, the section that applies to a node, the config it makes."""

from dataclasses import dataclass
from pathlib import Path
import re
from typing import Any, Optional, Sequence, TYPE_CHECKING, Union

from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, ParameterType

import yaml

if TYPE_CHECKING:
    from tskf_ros.messages.parameter_schema import ParameterSchema

__all__ = ['descriptor', 'file_values', 'float_range', 'given_parameters', 'IGNORED',
           'IGNORED_PREFIX', 'NodeConfig', 'parameters_for_node', 'ParamsError',
           'parameter_values', 'read_params_yaml', 'section_applies']


class _RclLoader(getattr(yaml, 'CSafeLoader', yaml.SafeLoader)):  # type: ignore[misc]
    """
    YAML as rcl's parameter parser reads it: 1e-3 and 1.0e3 are floats (YAML 1.1: str).

    libyaml's parser where PyYAML has it (CSafeLoader: the same documents, read 3 to 5
    times faster; a node reads its parameter schema at start), else PyYAML's own.
    """


_RclLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$'),
    list('-+0123456789.'))


def read_params_yaml(text: str) -> Any:
    """Parse a parameter file's text as the node would read its numbers."""
    return yaml.load(text, Loader=_RclLoader)  # noqa: S506 - a SafeLoader subclass


def float_range(lo: float, hi: float) -> dict:
    """Return ParameterDescriptor keyword arguments for a closed floating-point range."""
    return {'floating_point_range': [FloatingPointRange(from_value=lo, to_value=hi)]}


def descriptor(text: str, rng: Optional[tuple] = None,
               type_: int = ParameterType.PARAMETER_DOUBLE, *,
               read_only: bool = True) -> ParameterDescriptor:
    """Describe a parameter: its text, type, optional float range (lo, hi) and read-only flag."""
    return ParameterDescriptor(description=text, type=type_, read_only=read_only,
                               **(float_range(*rng) if rng is not None else {}))


@dataclass(frozen=True)
class NodeConfig:
    """A filtering node's settings, read once: its session's config and its own."""

    session: Any                 # EstimatorConfig or AlignmentConfig
    frame_id: str
    diagnostics_period: float    # the parameter diagnostic_updater.period
    queue_depth: int
    status_period: float = 10.0  # s between two INFO status lines; 0: none


# parameters every node has that the offline adapters do not use: rclpy's own, and the
# QoS overrides of its publishers and subscriptions (qos_overrides./topic.publisher.depth)
IGNORED = frozenset({'use_sim_time', 'start_type_description_service'})
IGNORED_PREFIX = 'qos_overrides.'


class ParamsError(ValueError):
    """A parameter file that cannot configure the filter."""


def parameter_values(params_file: Optional[Union[str, Path]], schema: 'ParameterSchema',
                     overrides: Optional[dict] = None) -> dict:
    """
    Return a node's defaults overridden by the file's section for it, then by overrides.

    schema is the node's ParameterSchema (messages/parameter_schema.py); the section is
    the first of `node`, `/node`, `/**/node` and `/**` that has `ros__parameters`.  Every
    value is checked against the schema as the node checks it (type, range, choices).
    Raises ParamsError naming the file and the problem: unreadable, no section, a
    parameter the node does not have, or a value it refuses.
    """
    node_name = schema.node
    values = schema.defaults()
    where = str(params_file) if params_file else 'parameters'
    if params_file:
        try:
            doc = read_params_yaml(Path(params_file).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise ParamsError(f'{params_file}: cannot read parameters ({exc})') from None
        if not isinstance(doc, dict):
            raise ParamsError(f'{params_file}: not a parameter file (a YAML mapping)')
        section = None
        for key in (node_name, '/' + node_name, '/**/' + node_name, '/**'):
            if isinstance(doc.get(key), dict) and 'ros__parameters' in doc[key]:
                section = doc[key]['ros__parameters']
                break
        if not isinstance(section, dict):
            raise ParamsError(f'{params_file}: no {node_name}: ros__parameters section')
        given = {name: value for name, value in _flat(section).items()
                 if name not in IGNORED and not name.startswith(IGNORED_PREFIX)}
        unknown = sorted(set(given) - set(values))
        if unknown:
            raise ParamsError(f'{params_file}: unknown parameter(s) {", ".join(unknown)}')
        values.update(given)
    values.update(overrides or {})
    try:
        return schema.check(values)
    except ValueError as exc:
        raise ParamsError(f'{where}: {exc}') from None


def _flat(parameters: dict, prefix: str = '') -> dict:
    """Return a ros__parameters mapping with nested names dotted (a.b: 1 -> {'a.b': 1})."""
    out = {}
    for key, value in parameters.items():
        name = prefix + str(key)
        if isinstance(value, dict):
            out.update(_flat(value, name + '.'))
        else:
            out[name] = value
    return out


def flat_parameters(parameters: dict, prefix: str = '') -> dict:
    """Return a ros__parameters mapping with nested namespaces as dotted names."""
    out = {}
    for key, value in parameters.items():
        name = prefix + str(key)
        out.update(flat_parameters(value, name + '.') if isinstance(value, dict)
                   else {name: value})
    return out


def section_applies(key: str, node_fqn: str) -> bool:
    """
    Return whether a parameter file's section `key` applies to the node node_fqn, as in rcl.

    A key without a leading '/' gets one; a '**' token stands for any number of namespace
    tokens (none too), a '*' token for exactly one; other tokens match themselves.
    """
    tokens = ('/' + key.strip('/')).split('/')[1:]
    wild = {'**': r'(?:/\w+)*', '*': r'/\w+'}
    pattern = ''.join(wild.get(t, '/' + re.escape(t)) for t in tokens)
    return re.fullmatch(pattern, node_fqn, re.ASCII) is not None


def _sections(doc: dict, path: tuple = ()) -> list:
    """Return (node key, ros__parameters) of every section, namespaces nested or not."""
    out = []
    for key, value in doc.items():
        if not isinstance(value, dict):
            continue
        here = path + (str(key).strip('/'),)
        if 'ros__parameters' in value:
            out.append(('/'.join(here), value['ros__parameters']))
        else:
            out.extend(_sections(value, here))
    return out


def _names(parameters: Any, prefix: str = '') -> set:
    """Return the dotted names of a ros__parameters mapping (nested: parameter namespaces)."""
    if not isinstance(parameters, dict):
        return set()
    names = set()
    for key, value in parameters.items():
        name = prefix + str(key)
        names |= _names(value, name + '.') if isinstance(value, dict) else {name}
    return names


def parameters_for_node(params_file: Union[str, Path], node_fqn: str) -> set:
    """
    Return the names of the parameters params_file sets for the node node_fqn (rcl's rules).

    Raises OSError or yaml.YAMLError if the file cannot be read.
    """
    doc = read_params_yaml(Path(params_file).read_text())
    if not isinstance(doc, dict):
        return set()
    return set().union(*(_names(params) for key, params in _sections(doc)
                         if section_applies(key, node_fqn)))


def file_values(params_file: Union[str, Path], node_fqn: str) -> dict:
    """
    Return {dotted name: value} of what params_file sets for the node node_fqn (rcl's rules).

    Later sections win.  Raises OSError or yaml.YAMLError if the file cannot be read.
    """
    doc = read_params_yaml(Path(params_file).read_text())
    values: dict = {}
    for key, params in _sections(doc) if isinstance(doc, dict) else ():
        if section_applies(key, node_fqn) and isinstance(params, dict):
            values.update(flat_parameters(params))
    return values


def given_parameters(argv: Sequence[str], node_name: str, node_fqn: str) -> dict:
    """
    Return {name: where it was given} of the parameters a command line sets for a node.

    Read as rcl reads them: in each `--ros-args ... [--]` section, `--params-file FILE`
    (the sections of FILE that apply to node_fqn) and `-p`/`--param NAME:=VALUE` (or
    `NODE:NAME:=VALUE`, for the node named NODE only).  A file that cannot be read is
    left out (rcl refuses it before the node starts).  Where a parameter is given twice,
    the place rcl takes it from: the last `-p` for it, else the last file that has it.
    """
    given: dict = {}
    ros = False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            ros = True
        elif arg == '--':
            ros = False
        elif ros and i + 1 < len(argv) and arg == '--params-file':
            try:
                names = parameters_for_node(argv[i + 1], node_fqn)
            except (OSError, yaml.YAMLError):
                continue
            given.update({name: argv[i + 1] for name in names
                          if not given.get(name, '').startswith('-')})
        elif ros and i + 1 < len(argv) and arg in ('-p', '--param') and ':=' in argv[i + 1]:
            name = argv[i + 1].split(':=', 1)[0]
            node, _, name = name.rpartition(':')
            if node in ('', node_name, node_fqn):
                given[name] = f'{arg} {argv[i + 1]}'
    return given
