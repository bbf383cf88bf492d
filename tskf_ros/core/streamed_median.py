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
np.median of values read a block at a time (from a temporary file), without keeping them.

The k-th smallest of n float64 values is found by radix selection on their bits, 16 at a
time: a float64's bits, the sign bit flipped for a positive number and all of them for a
negative one, order as the numbers do, so four passes over the values, each counting the
next 16 bits of those that share the bits found so far, give the k-th value exactly.  The
median is np.median's: the middle value, or the mean of the two middle ones (a + b) / 2;
NaN if any value is NaN.  (-0.0 and 0.0 are told apart here and not by np.median: a zero
median may differ in its sign.)

No ROS, no I/O.
"""

from typing import Callable, Iterable

import numpy as np
from numpy.typing import NDArray

__all__ = ['kth_smallest', 'median']

Blocks = Callable[[], Iterable[NDArray[np.float64]]]

_BITS = 16
_SIGN = np.uint64(1 << 63)


def _keys(values: NDArray[np.float64]) -> NDArray[np.uint64]:
    """Return keys that order as the values do (the sign bit flipped, or all bits if negative)."""
    bits = np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)
    return np.where(bits & _SIGN, ~bits, bits | _SIGN)


def _value(key: int) -> float:
    """Return the float64 of a key."""
    k = np.uint64(key)
    bits = k & ~_SIGN if k & _SIGN else ~k
    return float(np.array([bits], dtype=np.uint64).view(np.float64)[0])


def kth_smallest(blocks: Blocks, k: int) -> float:
    """Return the k-th smallest (from 0) of the values blocks() yields (it is called 4 times)."""
    prefix, found = 0, 0
    for shift in range(64 - _BITS, -1, -_BITS):
        counts = np.zeros(1 << _BITS, np.int64)
        for block in blocks():
            keys = _keys(np.asarray(block).reshape(-1))
            if found:
                keys = keys[(keys >> np.uint64(shift + _BITS)) == np.uint64(prefix)]
            counts += np.bincount(((keys >> np.uint64(shift)) & np.uint64((1 << _BITS) - 1))
                                  .astype(np.int64), minlength=1 << _BITS)
        below = np.cumsum(counts)
        digit = int(np.searchsorted(below, k, side='right'))
        if digit >= len(below):
            raise IndexError(f'the {k}-th of {int(below[-1])} values')
        k -= int(below[digit - 1]) if digit else 0
        prefix, found = (prefix << _BITS) | digit, found + _BITS
    return _value(prefix)


def median(blocks: Blocks) -> float:
    """Return np.median of the values blocks() yields (called up to 9 times), in bounded memory."""
    n, nan = 0, False
    for block in blocks():
        block = np.asarray(block, dtype=np.float64)
        n += block.size
        nan = nan or bool(np.isnan(block).any())
    if n == 0 or nan:
        return float('nan')
    if n % 2:
        return kth_smallest(blocks, n // 2)
    a, b = np.float64(kth_smallest(blocks, n // 2 - 1)), np.float64(kth_smallest(blocks, n // 2))
    return float((a + b) / 2)
