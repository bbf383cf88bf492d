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
"""Names the nodes share (a topic, a service, diagnostic task names), free of imports."""

__all__ = ['OUTPUT_FREQUENCY', 'POWER_METER', 'RESET_SERVICE', 'TRUTH_TOPIC']

# the evaluation truth of both simulators
TRUTH_TOPIC = 'true_angle'
# every filtering node's and the driver's: restart the session
RESET_SERVICE = '~/reset'
# diagnostic tasks of the simulators and the power meter driver
OUTPUT_FREQUENCY = 'output frequency'
POWER_METER = 'power meter'
