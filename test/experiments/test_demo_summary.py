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

"""The demo's figures against a hand-made record whose errors are known."""

from dataclasses import dataclass, field
import math

import pytest

from tskf_ros.core.units import NS
from tskf_ros.experiments.demo_summary import format_summary, summarise


@dataclass
class Record:
    """What summarise reads of the demo's collector: dicts from stamp (ns) to value."""

    truth: dict = field(default_factory=dict)
    power: dict = field(default_factory=dict)
    predicted: dict = field(default_factory=dict)
    corrected: dict = field(default_factory=dict)


def make_record() -> Record:
    # truth 0.1 rad at t = 0..9 s, every second; samples missing at 4, 5 and 6 s (a 4 s
    # jump before t = 7); the predictor 0.02 rad off, the corrector 0.01 rad, except a
    # 0.2 rad miss of the predictor at t = 7 (right after the jump)
    r = Record()
    for k in range(10):
        t = k * NS
        r.truth[t] = (0.1, 'stamp')          # collector rows may carry more than the value
        if k in (4, 5, 6):
            continue
        r.power[t] = 1.0
        r.predicted[t] = 0.1 + (0.2 if k == 7 else 0.02)
        r.corrected[t] = 0.1 + 0.01
    return r


def test_counts_gaps_and_rms_against_a_closed_form():
    s = summarise(make_record(), period=1.0)
    assert (s.samples, s.published, s.predicted, s.corrected) == (10, 7, 7, 7)
    assert s.gaps == [(pytest.approx(7.0), pytest.approx(4.0))]
    # 6 errors of 0.02 and one of 0.2 over 7 points; 0.01 everywhere
    assert s.rms_predicted == pytest.approx(math.sqrt((6 * 0.02 ** 2 + 0.2 ** 2) / 7), rel=1e-12)
    assert s.rms_corrected == pytest.approx(0.01, rel=1e-9)
    t, J, truth, pred, corr = s.worst[0]
    assert (t, J, truth) == (pytest.approx(7.0), pytest.approx(4.0), 0.1)
    assert pred == pytest.approx(0.3) and corr == pytest.approx(0.11)
    assert len(s.worst) == 5


def test_no_common_stamp_gives_nan_not_an_error():
    r = make_record()
    r.corrected = {}
    s = summarise(r, period=1.0)
    assert math.isnan(s.rms_predicted) and math.isnan(s.rms_corrected) and s.worst == []
    assert 'gaps (J > 1.5 s): 1: J = 4 s before t = 7' in format_summary(s)
