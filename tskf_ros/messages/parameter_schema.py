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

"""A node's parameters from its generate_parameter_library YAML schema: declare, check, list."""

import array
from dataclasses import dataclass, field, replace
from functools import lru_cache
import math
from pathlib import Path
from typing import Any, NamedTuple, Optional, Sequence

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from tskf_ros.messages.parameter_validation import (DOUBLE, format_number, INT64, out_of_reach,
                                                    RANGES, VALIDATORS)
from tskf_ros.messages.parameters import read_params_yaml

import yaml

__all__ = ['load_schema', 'ParameterError', 'ParameterSchema', 'ParameterSpec', 'SCHEMA_DIR',
           'schema_path', 'SchemaFormatError', 'TableRow', 'TYPES']

# config/schema/ of the source tree (an editable install), else share/tskf_ros/config/schema
SCHEMA_DIR = Path(__file__).resolve().parents[2] / 'config' / 'schema'
# generate_parameter_library's type names -> rclpy's parameter types
TYPES = {
    'bool': Parameter.Type.BOOL, 'int': Parameter.Type.INTEGER,
    'double': Parameter.Type.DOUBLE, 'string': Parameter.Type.STRING,
    'bool_array': Parameter.Type.BOOL_ARRAY, 'int_array': Parameter.Type.INTEGER_ARRAY,
    'double_array': Parameter.Type.DOUBLE_ARRAY, 'string_array': Parameter.Type.STRING_ARRAY,
}
# the keys a parameter (a leaf of the schema) may have
LEAF_KEYS = frozenset({'type', 'default_value', 'description', 'read_only', 'validation',
                       'additional_constraints'})
# the largest finite double: the open end of a one-sided range in a descriptor
BIG = DOUBLE[1]
# the types whose values are numbers
NUMBERS = frozenset({'int', 'double', 'int_array', 'double_array'})


class SchemaFormatError(ValueError):
    """A schema file that is not generate_parameter_library's format (a packaging error)."""


class ParameterError(ValueError):
    """A parameter value the schema refuses: one line naming the parameter and the rule."""


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter of a schema: a leaf of the YAML tree, named by its dotted path."""

    name: str
    type_name: str                   # a key of TYPES
    default: Any                     # None: no default_value (the parameter must be given)
    description: str = ''
    read_only: bool = False
    validation: tuple = ()           # ((validator name, (arguments...)), ...) in file order
    additional_constraints: str = ''

    @property
    def ros_type(self) -> Parameter.Type:
        """Return the rclpy parameter type."""
        return TYPES[self.type_name]

    def closed_range(self) -> Optional[tuple]:
        """Return the (lo, hi) a descriptor's range can say, from bounds<>/gt_eq<>/lt_eq<>."""
        if self.type_name not in ('int', 'double'):
            return None
        lo = hi = None
        for name, args in self.validation:
            if name == 'bounds':
                lo, hi = args
            elif name == 'gt_eq':
                lo = args[0]
            elif name == 'lt_eq':
                hi = args[0]
        if lo is None and hi is None:
            return None
        ends = INT64 if self.type_name == 'int' else (-BIG, BIG)
        return (ends[0] if lo is None else lo, ends[1] if hi is None else hi)

    def constraints_text(self) -> str:
        """Return every validation as text ('1e-6 to 3600', 'one of euler, exact')."""
        return '; '.join(VALIDATORS[name].doc(*args) for name, args in self.validation)

    def descriptor(self) -> ParameterDescriptor:
        """Return the ParameterDescriptor: type, description, read_only, range, constraints."""
        d = ParameterDescriptor(name=self.name, type=self.ros_type.value,
                                description=self.description, read_only=self.read_only,
                                additional_constraints=(self.additional_constraints
                                                        or self.constraints_text()))
        rng = self.closed_range()
        if rng is not None and self.type_name == 'double':
            d.floating_point_range = [FloatingPointRange(from_value=float(rng[0]),
                                                         to_value=float(rng[1]))]
        elif rng is not None:
            d.integer_range = [IntegerRange(from_value=int(rng[0]), to_value=int(rng[1]))]
        return d

    def coerce(self, value: Any) -> Any:
        """
        Return value as this parameter's type, or raise ParameterError.

        An integer is taken for a double (`-p rate:=5`), integers for a double array, and an
        empty list for any array; nothing else changes type (a bool is no integer).  An
        array.array (what a SetParameters request's array values arrive as) is a list.  An
        integer beyond an int64, or for a double beyond a double, is out of range.
        """
        if isinstance(value, array.array):
            value = value.tolist()
        t = self.type_name
        if t in NUMBERS:
            why = self.out_of_reach(value, DOUBLE if t.startswith('double') else INT64)
            if why:
                raise ParameterError(why)
        if t == 'double' and type(value) is int:
            return float(value)
        # Python's bool is an int, and rclpy's type check takes True for an integer: refused
        if (t == 'int' and isinstance(value, bool)) or (
                t == 'int_array' and isinstance(value, (list, tuple))
                and any(isinstance(e, bool) for e in value)):
            raise ParameterError(f'{self.name} must be {_article(t)}, got {value!r}')
        if t.endswith('_array') and isinstance(value, (list, tuple)):
            value = list(value)
            if t == 'double_array' and all(type(e) in (int, float) for e in value):
                return [float(e) for e in value]
            if not value:
                return value
        if not self.ros_type.check(value):
            raise ParameterError(f'{self.name} must be {_article(t)}, got {value!r}')
        return value

    def out_of_reach(self, value: Any, ends: tuple) -> str:
        """Return why value holds an integer outside ends (INT64, DOUBLE); '' if none."""
        return out_of_reach(self.name, value, ends, self.closed_range())

    def problem(self, value: Any) -> str:
        """Return why value breaks this parameter's type or validation; '' if it does not."""
        try:
            value = self.coerce(value)
        except ParameterError as exc:
            return str(exc)
        if self.type_name == 'double' and not math.isfinite(value) and self.validation:
            return f'{self.name} must be finite, got {value!r}'
        for name, args in self.validation:
            if not VALIDATORS[name].check(value, *args):
                rule = VALIDATORS[name].must(*args)
                if name in RANGES:
                    return f'{self.name} = {format_number(value)} is out of range: it must {rule}'
                return f'{self.name} must {rule}, got {value!r}'
        return ''

    def default_text(self) -> str:
        """Return the default as the node pages show it ('' for an empty string)."""
        value = self.default
        if value is None:
            return '(required)'
        if isinstance(value, bool):
            return str(value).lower()
        if isinstance(value, list):
            return '[' + ', '.join(format_number(e) if not isinstance(e, str) else e
                                   for e in value) + ']'
        if isinstance(value, str):
            return value or "''"
        return format_number(value)


def _article(type_name: str) -> str:
    words = {'bool': 'a bool', 'int': 'an integer', 'double': 'a number',
             'string': 'a string', 'bool_array': 'a list of bools',
             'int_array': 'a list of integers', 'double_array': 'a list of numbers',
             'string_array': 'a list of strings'}
    return words[type_name]


class TableRow(NamedTuple):
    """One parameter as the node pages list it."""

    name: str
    type_name: str
    default: str
    constraints: str
    read_only: bool
    description: str


@dataclass(frozen=True)
class ParameterSchema:
    """The parameters of one node, in the order of its schema file."""

    node: str
    parameters: dict = field(default_factory=dict)      # dotted name -> ParameterSpec

    @property
    def names(self) -> tuple:
        """Return every parameter's name, dotted for a nested one, in file order."""
        return tuple(self.parameters)

    def defaults(self) -> dict:
        """Return the default value of every parameter (a fresh copy: lists may be changed)."""
        return {name: (list(p.default) if isinstance(p.default, list) else p.default)
                for name, p in self.parameters.items()}

    def table_rows(self) -> list:
        """Return a TableRow per parameter, in file order (the node pages' tables)."""
        return [TableRow(p.name, p.type_name, p.default_text(), p.constraints_text(), p.read_only,
                         p.description) for p in self.parameters.values()]

    def check(self, values: dict) -> dict:
        """
        Return values coerced to the schema's types; raise ParameterError on the first bad one.

        Names the schema does not have are refused too.  This is what an offline tool
        applies to a parameter file or `--set` values: the rules the node applies.
        """
        unknown = sorted(set(values) - set(self.parameters))
        if unknown:
            raise ParameterError(f'{self.node} has no parameter(s) {", ".join(unknown)}')
        out = {}
        for name, value in values.items():
            why = self.parameters[name].problem(value)
            if why:
                raise ParameterError(why)
            out[name] = self.parameters[name].coerce(value)
        return out

    def refusal(self, changes: Sequence[Parameter]) -> str:
        """Return why a proposed change breaks the schema; '' if it does not (on-set callback)."""
        for p in changes:
            spec = self.parameters.get(p.name)
            if spec is not None:
                why = spec.problem(p.value)
                if why:
                    return why
        return ''

    def validate(self, changes: Sequence[Parameter]) -> SetParametersResult:
        """Return the on-set-parameters result of a proposed change: refused with the reason."""
        why = self.refusal(changes)
        return SetParametersResult(successful=not why, reason=why)

    def coerce_changes(self, changes: Sequence[Parameter]) -> list:
        """Return the changes with integers made doubles where the schema says double."""
        out = []
        for p in changes:
            spec = self.parameters.get(p.name)
            if spec is not None and p.type_ != spec.ros_type \
                    and p.type_ != Parameter.Type.NOT_SET:
                try:
                    p = Parameter(p.name, spec.ros_type, spec.coerce(p.value))
                except ParameterError:
                    pass            # refused by rclpy's type check, with its own reason
            out.append(p)
        return out

    def declare(self, node: Node) -> frozenset:
        """
        Declare every parameter on node with its descriptor; return the names given at start.

        Public rclpy calls only.  Every parameter is first declared without a value and with
        dynamic typing, so that rclpy hands it the value given at start (a parameter file,
        `-p`, a launch file, the node's parameter_overrides) if there is one: that is how
        the node learns which parameters were given.  That value, coerced to the schema's
        type (an integer for a double), or else the default, is checked against the
        schema; then the parameters are declared again with their static types, values
        and descriptors (read-only ones read-only), all in one `declare_parameters` call
        each time.  Raises ParameterError naming the first bad value.  Later changes of a
        double to an integer are taken as doubles too (a pre-set callback).  rclpy publishes
        the value given before the node sees it, and fails on an integer beyond an int64
        (a SystemError): an on-set callback refuses such a value first, as out of range.
        """
        names = self.names
        node.add_on_set_parameters_callback(self._carried)
        try:
            starts = node.declare_parameters(
                '', [(name, None, ParameterDescriptor(dynamic_typing=True)) for name in names])
        finally:
            node.remove_on_set_parameters_callback(self._carried)
        given, values = [], []
        defaults = self.defaults()
        for name, start in zip(names, starts):
            spec = self.parameters[name]
            if start.type_ != Parameter.Type.NOT_SET:
                given.append(name)
                value = start.value
            elif spec.default is None:
                raise ParameterError(f'{name} has no default: give it a value')
            else:
                value = defaults[name]
            why = spec.problem(value)
            if why:
                raise ParameterError(why)
            values.append(spec.coerce(value))
        for name in names:
            node.undeclare_parameter(name)
        # rclpy takes a parameter's static type from its value, and an empty list has none:
        # such a parameter is declared by its type, then set
        empty = {name for name, value in zip(names, values) if value == []}
        node.declare_parameters('', [
            (name, value, self.parameters[name].descriptor()) if name not in empty else
            (name, self.parameters[name].ros_type, self._writable(name))
            for name, value in zip(names, values)], ignore_override=True)
        for name in empty:
            spec = self.parameters[name]
            result = node.set_parameters([Parameter(name, spec.ros_type, [])])[0]
            if not result.successful:
                raise ParameterError(f'{name}: {result.reason}')
            if spec.read_only:
                node.set_descriptor(name, spec.descriptor())
        node.add_pre_set_parameters_callback(self.coerce_changes)
        return frozenset(given)

    def _carried(self, changes: Sequence[Parameter]) -> SetParametersResult:
        """Raise ParameterError for a value given with an integer an int64 cannot hold."""
        for p in changes:
            spec = self.parameters.get(p.name)
            if spec is not None and out_of_reach(p.name, p.value, INT64):
                raise ParameterError(spec.out_of_reach(p.value, INT64)
                                     if spec.type_name in NUMBERS else spec.problem(p.value))
        return SetParametersResult(successful=True)

    def _writable(self, name: str) -> ParameterDescriptor:
        """Return a parameter's descriptor, not read-only (to set it once declared)."""
        descriptor = self.parameters[name].descriptor()
        descriptor.read_only = False
        return descriptor


def _leaves(tree: dict, prefix: str, where: str) -> list:
    """Return (dotted name, leaf mapping) of every parameter below tree, in file order."""
    out = []
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if not isinstance(value, dict):
            raise SchemaFormatError(f'{where}: {name} is not a mapping')
        if isinstance(value.get('type'), str):
            out.append((name, value))
        else:
            out.extend(_leaves(value, name + '.', where))
    return out


def _validation(name: str, rules: Any, where: str) -> tuple:
    """Return ((validator, args), ...) of a leaf's `validation` mapping."""
    if rules is None:
        return ()
    if not isinstance(rules, dict):
        raise SchemaFormatError(f'{where}: {name}: validation must be a mapping')
    out = []
    for key, args in rules.items():
        base = str(key).split('<', 1)[0]
        if base not in VALIDATORS:
            raise SchemaFormatError(f'{where}: {name}: unknown validation {key!r} (known: '
                                    f'{", ".join(f"{v}<>" for v in VALIDATORS)})')
        args = tuple(args or ())
        if len(args) != VALIDATORS[base].arity:
            raise SchemaFormatError(f'{where}: {name}: {key} takes {VALIDATORS[base].arity} '
                                    f'argument(s), got {list(args)}')
        out.append((base, tuple(tuple(a) if isinstance(a, list) else a for a in args)))
    return tuple(out)


def parse_schema(doc: Any, where: str = 'schema') -> ParameterSchema:
    """Return the schema of a parsed YAML document: {node name: {parameters...}}."""
    if not isinstance(doc, dict) or len(doc) != 1:
        raise SchemaFormatError(f'{where}: one top-level key (the node name) expected')
    (node, tree), = doc.items()
    if not isinstance(tree, dict) or not tree:
        raise SchemaFormatError(f'{where}: {node} declares no parameter')
    params = {}
    for name, leaf in _leaves(tree, '', where):
        extra = sorted(set(leaf) - LEAF_KEYS)
        if extra:
            raise SchemaFormatError(f'{where}: {name}: unknown key(s) {", ".join(extra)}')
        if leaf['type'] not in TYPES:
            raise SchemaFormatError(f'{where}: {name}: type {leaf["type"]!r} is not one of '
                                    f'{", ".join(TYPES)}')
        spec = ParameterSpec(
            name=name, type_name=leaf['type'], default=None,
            description=' '.join(str(leaf.get('description', '')).split()),
            read_only=bool(leaf.get('read_only', False)),
            validation=_validation(name, leaf.get('validation'), where),
            additional_constraints=str(leaf.get('additional_constraints', '')))
        if 'default_value' in leaf:
            try:
                default = spec.coerce(leaf['default_value'])
            except ParameterError as exc:
                raise SchemaFormatError(f'{where}: default_value: {exc}') from None
            spec = replace(spec, default=default)
            why = spec.problem(default)
            if why:
                raise SchemaFormatError(f'{where}: default_value: {why}')
        params[name] = spec
    return ParameterSchema(str(node), params)


def schema_path(node: str) -> Path:
    """Return config/schema/<node>.yaml of the source tree, else of the installed package."""
    here = SCHEMA_DIR / f'{node}.yaml'
    if here.is_file():
        return here
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('tskf_ros')) / 'config' / 'schema' / f'{node}.yaml'


@lru_cache(maxsize=None)
def load_schema(node: str) -> ParameterSchema:
    """Return the parameter schema of a node of this package (read once per process)."""
    path = schema_path(node)
    try:
        doc = read_params_yaml(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SchemaFormatError(f'{path}: cannot read the parameter schema ({exc})') from None
    return parse_schema(doc, str(path))
