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

"""
Run a console script or a Python file with start-up marks: bench/bench_startup.py's (b).

    python bench/startup_marks.py SCRIPT [ARGS...]

with BENCH_STARTUP_MARKS=FILE, BENCH_STARTUP_INPUT=TOPIC and BENCH_STARTUP_OUTPUT=TOPIC
in its environment (bench/bench_startup.py sets them).

Runs SCRIPT as __main__ (what its shebang's interpreter would run), after wrapping three
public rclpy calls, each only until its first call: `SingleThreadedExecutor.spin_once`
(the process has built its node and waits for input: `ready`), the callback of the
subscription on TOPIC INPUT (`input`, when its first message is handed over) and
`Publisher.publish` on the topic OUTPUT (`output`).  At `output` it writes one JSON line
to FILE: the three instants on CLOCK_MONOTONIC (time.monotonic, one clock for every
process of the machine) and the process's CPU time (all threads) so far.  The process's
own start is then (ready - spawn) + (output - input): its time to be ready, plus its
handling of the first input, without the wait for the middleware's discovery between
the two.  Imports rclpy first (every measured process imports it anyway).
"""

import json
import os
import runpy
import sys
import time

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher

MARKS = os.environ.get('BENCH_STARTUP_MARKS', '')
INPUT = os.environ.get('BENCH_STARTUP_INPUT', '').strip('/')
OUTPUT = '/' + os.environ.get('BENCH_STARTUP_OUTPUT', '').strip('/')
marks: dict = {}

_spin_once = SingleThreadedExecutor.spin_once
_create_subscription = Node.create_subscription
_publish = Publisher.publish


def spin_once(self, *args, **kwargs):
    """Mark the first turn of the executor (the node is built), then spin as rclpy does."""
    marks.setdefault('ready', time.monotonic())
    SingleThreadedExecutor.spin_once = _spin_once
    return _spin_once(self, *args, **kwargs)


def create_subscription(self, msg_type, topic, callback, *args, **kwargs):
    """Create the subscription; on the input topic, mark its first message's hand-over."""
    if topic.strip('/') == INPUT:
        def first(msg, _callback=callback):
            marks.setdefault('input', time.monotonic())
            return _callback(msg)
        callback = first
    return _create_subscription(self, msg_type, topic, callback, *args, **kwargs)


def publish(self, msg):
    """Publish; on the output topic, mark the first call and write the marks."""
    if self.topic_name == OUTPUT and 'output' not in marks:
        marks['output'] = time.monotonic()
        marks['cpu'] = time.process_time()
        Publisher.publish = _publish
        with open(MARKS, 'w') as f:
            f.write(json.dumps(marks) + '\n')
    return _publish(self, msg)


def main() -> None:
    """Wrap the three calls, then run the script as __main__ with its own argv."""
    marks['main'] = time.monotonic()
    SingleThreadedExecutor.spin_once = spin_once
    Node.create_subscription = create_subscription
    Publisher.publish = publish
    sys.argv = sys.argv[1:]
    runpy.run_path(sys.argv[0], run_name='__main__')


if __name__ == '__main__':
    main()
