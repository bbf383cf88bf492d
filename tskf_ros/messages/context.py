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

"""Ending an rclpy context when a signal handler may end it at the same moment."""

from typing import Optional

import rclpy
from rclpy.context import Context


def end_context(context: Optional[Context] = None) -> None:
    """
    Shut a context down (the default one if None), quietly if it is already shut down.

    `rclpy.try_shutdown` checks `ok()` and then shuts down; rclpy's SIGINT/SIGTERM handler
    may shut the context down between the two, and rcl then raises "rcl_shutdown already
    called" (RCLError, a RuntimeError).  That is the end we asked for, not a failure.
    """
    try:
        rclpy.try_shutdown(context=context)
    except RuntimeError:
        if (context or rclpy.get_default_context()).ok():
            raise
