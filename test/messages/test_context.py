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

"""end_context: a context already shut down (by a signal handler, in a race) ends quietly."""

import pytest
import rclpy
from rclpy.context import Context

from tskf_ros.messages.context import end_context


class RacingContext(Context):
    """A context whose signal handler shuts it down between try_shutdown's check and call."""

    def try_shutdown(self) -> None:
        """Shut down as the handler would, then report the second shutdown as rcl does."""
        self.shutdown()
        raise RuntimeError('failed to shutdown: rcl_shutdown already called on the given '
                           'context')


class StuckContext(Context):
    """A context that fails to shut down and stays up: a real failure."""

    def try_shutdown(self) -> None:
        """Fail while the context is still up."""
        raise RuntimeError('rcl failed')


def test_a_context_shut_down_in_between_ends_quietly() -> None:
    context = RacingContext()
    rclpy.init(context=context)
    end_context(context)
    assert not context.ok()


def test_a_context_already_shut_down_ends_quietly() -> None:
    context = Context()
    rclpy.init(context=context)
    context.shutdown()
    end_context(context)
    assert not context.ok()


def test_a_failure_with_the_context_still_up_is_raised() -> None:
    context = StuckContext()
    rclpy.init(context=context)
    try:
        with pytest.raises(RuntimeError, match='rcl failed'):
            end_context(context)
        assert context.ok()
    finally:
        context.shutdown()
