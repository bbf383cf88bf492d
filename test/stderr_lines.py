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

"""What a tool printed on stderr: no traceback, one line, an argparse usage error."""


def error_lines(err: str) -> list:
    """Return the non-empty lines of stderr; there must be no traceback."""
    assert 'Traceback' not in err, err
    return [line for line in err.splitlines() if line.strip()]


def one_line(err: str, prefix: str = '', *words: str) -> str:
    """Check that stderr is exactly one line, starting with prefix, holding every word."""
    lines = error_lines(err)
    assert len(lines) == 1, err
    assert lines[0].startswith(prefix), lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def usage_error(err: str, prog: str, text: str) -> None:
    """Check an argparse usage error: usage lines, then exactly `prog: error: text`."""
    lines = error_lines(err)
    assert lines[0].startswith(f'usage: {prog}'), err
    assert lines[-1] == f'{prog}: error: {text}', err
