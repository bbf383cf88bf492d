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
numpy's sum of n float64 values, given a block at a time, without keeping them.

np.sum of a contiguous float64 array is pairwise: n values are summed by halves, the
first half n // 2 rounded down to a multiple of 8, until at most 128 are left, which
are summed with eight accumulators.  `PairwiseSum(n)` follows the same halving down to
leaves of at most LEAF values, sums each leaf with np.add.reduce as it is completed (so
numpy sums it exactly as it would that part of the whole array) and adds the leaves'
sums up the same tree: the result is np.sum's, bit for bit, with one leaf held
(test/core/test_pairwise_sum.py checks it against np.sum).

No ROS, no I/O.
"""

from typing import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ['LEAF', 'PairwiseSum']

# values summed at once (a multiple of 8 and at least numpy's 128-value block)
LEAF = 65536


def _half(n: int) -> int:
    """Return the size of the first half of n values, as numpy's pairwise sum splits them."""
    n2 = n // 2
    return n2 - n2 % 8


def leaf_sizes(n: int, leaf: int = LEAF) -> list[int]:
    """Return the sizes of the leaves of n values, in order."""
    if n <= leaf:
        return [n]
    n2 = _half(n)
    return leaf_sizes(n2, leaf) + leaf_sizes(n - n2, leaf)


def _combine(n: int, leaf: int, sums: Iterator[np.float64]) -> np.float64:
    """Add the leaves' sums up the tree of n values."""
    if n <= leaf:
        return next(sums)
    n2 = _half(n)
    first = _combine(n2, leaf, sums)
    return first + _combine(n - n2, leaf, sums)


class PairwiseSum:
    """np.sum of n float64 values given in order (`add`), one leaf kept; `total()` at the end."""

    def __init__(self, n: int, leaf: int = LEAF) -> None:
        if leaf < 128 or leaf % 8:
            raise ValueError(f'leaf {leaf}: a multiple of 8, at least 128')
        self.n, self.leaf = int(n), leaf
        self.sizes = leaf_sizes(self.n, leaf)
        self.sums: list[np.float64] = []
        self.buffer = np.empty(min(self.n, leaf))
        self.fill = 0
        self.given = 0

    def add(self, values: ArrayLike) -> None:
        """Add the next values (in the order of the whole)."""
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if self.given + values.size > self.n:
            raise ValueError(f'more than the {self.n} values announced')
        self.given += values.size
        i = 0
        while i < values.size:
            size = self.sizes[len(self.sums)]
            take = min(size - self.fill, values.size - i)
            self.buffer[self.fill:self.fill + take] = values[i:i + take]
            self.fill += take
            i += take
            if self.fill == size:
                self._close_leaf()

    def _close_leaf(self) -> None:
        self.sums.append(np.add.reduce(self.buffer[:self.fill]))
        self.fill = 0

    def total(self) -> np.float64:
        """Return the sum (np.sum's) once all n values are given."""
        if self.given != self.n:
            raise ValueError(f'{self.given} of the {self.n} values announced were given')
        if self.n == 0:
            return np.float64(0.0)
        return _combine(self.n, self.leaf, iter(self.sums))


def pairwise_sum(blocks: Iterator[NDArray[np.float64]], n: int) -> np.float64:
    """Return np.sum of the n values that `blocks` yields in order."""
    acc = PairwiseSum(n)
    for block in blocks:
        acc.add(block)
    return acc.total()
