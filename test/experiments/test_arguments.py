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

"""The experiments' argparse types: in range is the value, out of range is one usage line."""

import argparse

import pytest

from tskf_ros.experiments import arguments


@pytest.mark.parametrize('text, want', [('0', [0.0]), ('0,0.5, 2.5', [0.0, 0.5, 2.5]),
                                        ('100', [100.0])])
def test_a_noise_list_in_range_is_its_values(text, want):
    assert arguments.noise_list(text) == want


@pytest.mark.parametrize('text', ['', ',', '1e308', 'nan', 'inf', '-0.1', '1,x', '100.001'])
def test_a_noise_list_out_of_range_is_refused(text):
    with pytest.raises(argparse.ArgumentTypeError):
        arguments.noise_list(text)


@pytest.mark.parametrize('parse, text, ok', [
    (arguments.rate_deg_s, '360', True), (arguments.rate_deg_s, '360.5', False),
    (arguments.angle_deg, '-180', True), (arguments.angle_deg, '-181', False),
    (arguments.seed, '4294967295', True), (arguments.seed, '4294967296', False),
    (arguments.count(1, 5), '0', False), (arguments.count(1, 5), '5', True),
    (arguments.number(0.0, 1.0, open_low=True), '0', False)])
def test_the_bounds_are_inclusive_as_documented(parse, text, ok):
    if ok:
        parse(text)
    else:
        with pytest.raises(argparse.ArgumentTypeError):
            parse(text)
