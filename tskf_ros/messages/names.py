# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
"""Names the nodes share (a topic, a service, diagnostic task names), free of imports."""

__all__ = ['OUTPUT_FREQUENCY', 'POWER_METER', 'RESET_SERVICE', 'TRUTH_TOPIC']

# the evaluation truth of both simulators
TRUTH_TOPIC = 'true_angle'
# every filtering node's and the driver's: restart the session
RESET_SERVICE = '~/reset'
# diagnostic tasks of the simulators and the power meter driver
OUTPUT_FREQUENCY = 'output frequency'
POWER_METER = 'power meter'
