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

"""A node started by run_node runs BLAS on one thread, whatever the environment says."""

import json
import os
from pathlib import Path
import subprocess
import sys

REPO = Path(__file__).resolve().parents[2]
# a node that prints the BLAS/OpenMP thread counts from its first callback, then stops
PROBE = '''
import json
import rclpy
from rclpy.node import Node
from threadpoolctl import threadpool_info
from tskf_ros.nodes.node_runner import run_node
from tskf_ros.nodes import timescale_estimator  # noqa: the estimator's libraries


def counts():
    return [i['num_threads'] for i in threadpool_info()]


class Probe(Node):
    def __init__(self):
        super().__init__('blas_probe')
        self.timer = self.create_timer(0.001, self.report)

    def report(self):
        self.timer.cancel()
        print(json.dumps({'in_node': counts()}), flush=True)
        rclpy.try_shutdown(context=self.context)


print(json.dumps({'before': counts()}), flush=True)
run_node(Probe, name='blas_probe', description='probe', args=['blas_probe'])
'''


def test_run_node_limits_blas_threads_to_one_without_openblas_num_threads():
    env = {k: v for k, v in os.environ.items()
           if k not in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')}
    result = subprocess.run([sys.executable, '-c', PROBE], cwd=REPO, env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    report = {}
    for line in result.stdout.splitlines():
        report.update(json.loads(line))
    assert report['in_node'] and set(report['in_node']) == {1}, report
    if (os.cpu_count() or 1) > 1:        # the default is one thread per core
        assert max(report['before']) > 1, report
