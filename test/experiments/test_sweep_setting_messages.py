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

"""What sweep's --set says about a value it cannot take: the kind the parameter wants."""

import pytest

from tskf_ros.experiments import sweep_tasks
from tskf_ros.messages.estimator_interface import default_parameters


@pytest.mark.parametrize('text, message', [
    ('gate_patience=x', "--set gate_patience: 'x' is not an integer"),
    ('gate_patience=2.5', "--set gate_patience: '2.5' is not an integer"),
    ('gate=abc', "--set gate: 'abc' is not a number"),
    ('R=1 x', "--set R: '1 x' is not a list of numbers"),
])
def test_a_value_of_the_wrong_kind_is_named_with_the_kind_wanted(text, message):
    with pytest.raises(ValueError) as info:
        sweep_tasks.parse_setting(text, default_parameters())
    assert str(info.value) == message


def test_a_list_of_names_takes_names():
    assert sweep_tasks.parse_setting('state_names=a,b c', default_parameters()) == (
        'state_names', [['a'], ['b', 'c']])
