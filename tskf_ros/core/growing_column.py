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

"""A column of rows of one shape and dtype, grown in place: what a long run keeps compactly."""

import numpy as np
from numpy.typing import DTypeLike, NDArray

__all__ = ['Column']

# rows a column grows by at least
GROW = 4096


class Column:
    """
    One column of a fixed row shape, grown in place (a large one by remapping pages).

    ndarray.resize grows an array in place (for a large array glibc's realloc moves pages,
    it does not copy them), so the memory held is about the rows written, not a list of
    objects: 8 bytes a float64 number.
    """

    def __init__(self, dtype: DTypeLike, shape: tuple[int, ...] = ()) -> None:
        self.data: NDArray = np.empty((0, *shape), dtype=dtype)
        self.count = 0

    def append(self, value: object) -> None:
        """Add a row at the end."""
        if self.count == self.data.shape[0]:
            size = max(self.count + GROW, self.count * 3 // 2)
            self.data.resize((size, *self.data.shape[1:]), refcheck=False)
        self.data[self.count] = value
        self.count += 1

    def view(self) -> NDArray:
        """Return the rows written (a view)."""
        return self.data[:self.count]

    def __len__(self) -> int:
        return self.count
