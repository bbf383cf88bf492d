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

"""A two-axis aligner that sees each sample through a function: a spike, a dropped reading."""

from typing import Callable, Optional

import numpy as np


class SampleFilter:
    """
    The aligner given each sample as `receive(stamp, z)` returns it (simulate_pan_tilt's).

    after(stamp), if given, runs after each step, to watch the aligner's state.
    """

    def __init__(self, aligner, receive: Callable[[float, np.ndarray], np.ndarray],
                 after: Optional[Callable[[float], None]] = None) -> None:
        self.aligner = aligner
        self.runs = aligner.runs
        self.receive = receive
        self.after = after

    @property
    def scan_offset(self):
        """Return the aligner's scan offset."""
        return self.aligner.scan_offset

    def step(self, stamp: float, z: np.ndarray) -> np.ndarray:
        """Step the aligner on the received sample; return its turn."""
        turn = self.aligner.step(stamp, self.receive(stamp, z))
        if self.after is not None:
            self.after(stamp)
        return turn
