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

"""mypy passes on the ROS-free layers (core/, owc/, led/) with the settings in setup.cfg."""

from pathlib import Path

from mypy import api

REPO = Path(__file__).resolve().parents[2]


def test_mypy_is_clean_on_core_owc_and_led(monkeypatch):
    monkeypatch.chdir(REPO)
    out, err, rc = api.run(['--config-file', str(REPO / 'setup.cfg')])
    assert rc == 0, out + err
