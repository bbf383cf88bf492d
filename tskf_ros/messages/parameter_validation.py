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

"""generate_parameter_library's validation functions (bounds<>, one_of<>, ...) and their texts."""

from dataclasses import dataclass
import math
import sys
from typing import Any, Callable, Optional, Sequence

__all__ = ['DOUBLE', 'format_number', 'INT64', 'out_of_reach', 'RANGES', 'Validator',
           'VALIDATORS']

# the numbers a ROS parameter carries: an integer is an int64, a number a double
INT64 = (-2 ** 63, 2 ** 63 - 1)
DOUBLE = (-sys.float_info.max, sys.float_info.max)


def format_number(value: Any) -> str:
    """
    Return a number as the docs and messages write it (1e-06 -> 1e-6, 3600.0 -> 3600).

    With the fewest significant digits that are the number exactly (1e8, 0.1), so never
    rounded: 100000001 (not 1e8), 0.1 + 0.2 as 0.30000000000000004.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return repr(value) if isinstance(value, str) else str(value)
    if isinstance(value, int):
        try:
            text = f'{value:g}'
        except OverflowError:       # beyond a double: every digit
            return str(value)
        if float(text) != value:
            return str(value)
        return _exponent(text)
    # the fewest digits that are the number; %g's six where as short (3600, not 3.6e3)
    if not math.isfinite(value):
        return str(value)
    fewest = next(t for t in (f'{value:.{p}g}' for p in range(1, 18)) if float(t) == value)
    six = f'{value:g}'
    return _exponent(six if float(six) == value and len(six) <= len(fewest) else fewest)


def _exponent(text: str) -> str:
    mantissa, _, exponent = text.partition('e')
    return f'{mantissa}e{int(exponent)}' if exponent else text


@dataclass(frozen=True)
class Validator:
    """One validation function of generate_parameter_library's YAML: its check and texts."""

    check: Callable[..., bool]
    doc: Callable[..., str]          # the rule as the node pages show it
    must: Callable[..., str]         # the rule after 'must' in a refusal
    arity: int


def _among(options: Sequence) -> str:
    return ', '.join(map(str, options))


_n = format_number

VALIDATORS = {
    'bounds': Validator(lambda v, lo, hi: lo <= v <= hi,
                        lambda lo, hi: f'{_n(lo)} to {_n(hi)}',
                        lambda lo, hi: f'be within [{_n(lo)}, {_n(hi)}]', 2),
    'gt': Validator(lambda v, x: v > x, lambda x: f'> {_n(x)}', lambda x: f'be > {_n(x)}', 1),
    'gt_eq': Validator(lambda v, x: v >= x, lambda x: f'>= {_n(x)}',
                       lambda x: f'be >= {_n(x)}', 1),
    'lt': Validator(lambda v, x: v < x, lambda x: f'< {_n(x)}', lambda x: f'be < {_n(x)}', 1),
    'lt_eq': Validator(lambda v, x: v <= x, lambda x: f'<= {_n(x)}',
                       lambda x: f'be <= {_n(x)}', 1),
    'one_of': Validator(lambda v, options: v in options,
                        lambda options: f'one of {_among(options)}',
                        lambda options: f'be one of {_among(options)}', 1),
    'not_empty': Validator(lambda v: len(v) > 0, lambda: 'not empty', lambda: 'not be empty', 0),
    'fixed_size': Validator(lambda v, n: len(v) == n, lambda n: f'{n} entries',
                            lambda n: f'have {n} entries', 1),
    'size_gt': Validator(lambda v, n: len(v) > n, lambda n: f'more than {n} entries',
                         lambda n: f'have more than {n} entries', 1),
    'size_lt': Validator(lambda v, n: len(v) < n, lambda n: f'fewer than {n} entries',
                         lambda n: f'have fewer than {n} entries', 1),
    'unique': Validator(lambda v: len(set(v)) == len(v), lambda: 'no duplicates',
                        lambda: 'have no duplicates', 0),
    'subset_of': Validator(lambda v, options: all(e in options for e in v),
                           lambda options: f'each one of {_among(options)}',
                           lambda options: f'have each entry one of {_among(options)}', 1),
    'element_bounds': Validator(lambda v, lo, hi: all(lo <= e <= hi for e in v),
                                lambda lo, hi: f'each {_n(lo)} to {_n(hi)}',
                                lambda lo, hi: f'have each entry within [{_n(lo)}, {_n(hi)}]',
                                2),
    'lower_element_bounds': Validator(lambda v, lo: all(e >= lo for e in v),
                                      lambda lo: f'each >= {_n(lo)}',
                                      lambda lo: f'have each entry >= {_n(lo)}', 1),
    'upper_element_bounds': Validator(lambda v, hi: all(e <= hi for e in v),
                                      lambda hi: f'each <= {_n(hi)}',
                                      lambda hi: f'have each entry <= {_n(hi)}', 1),
}

# the validations of a number's range (their refusals say 'out of range', as rclpy's do)
RANGES = frozenset({'bounds', 'gt', 'gt_eq', 'lt', 'lt_eq'})


def out_of_reach(name: str, value: Any, ends: tuple, closed: Optional[tuple] = None) -> str:
    """
    Return why value (a number or a list) holds an integer outside ends; '' if it does not.

    ends is what the parameter carries (INT64, or DOUBLE: an integer given for a double
    becomes one); the refusal names the parameter's own range, closed, if it has one.
    A bool is no integer here.
    """
    items = value if isinstance(value, (list, tuple)) else [value]
    bad = next((e for e in items if type(e) is int and not ends[0] <= e <= ends[1]), None)
    if bad is None:
        return ''
    note = '' if closed else ' (a double)' if ends == DOUBLE else ' (a 64-bit integer)'
    lo, hi = closed or ends
    within = f'within [{format_number(lo)}, {format_number(hi)}]{note}'
    if items is value:
        return (f'{name} has an entry out of range ({format_number(bad)}): each must be '
                f'{within}')
    return f'{name} = {format_number(bad)} is out of range: it must be {within}'
