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

"""Shared pytest setup: an isolated ROS 2 environment for every test run."""

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent
# Generated trees at the repository root that the linters never check.
NOT_LINTED = {'build', 'install', 'log', 'results'}

# Set at import time, before any test starts a subprocess or imports rclpy, so that every
# process of this run talks only on this machine and only in this run's own domain.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# one BLAS thread for this run's subprocesses too (./run sets it before Python starts)
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
if not os.environ.get('ROS_DOMAIN_ID'):
    os.environ['ROS_DOMAIN_ID'] = str(os.getpid() % 100 + 1)


# ros_context, ros_executor and start_node: the plugin tskf_ros.testing, which users get too


@pytest.fixture(params=['single', 'events'])
def executor_kind(request):
    """Return each executor a node can run on (tskf_ros.nodes.node_runner.EXECUTORS) in turn."""
    return request.param


@pytest.fixture
def lint_paths():
    """Return the repository's top-level source paths (no hidden, venv or generated trees)."""
    return sorted(
        str(path) for path in REPO_ROOT.iterdir()
        if not path.name.startswith('.') and path.name not in NOT_LINTED
        and not path.name.endswith('.egg-info')
        and (path.is_dir() or path.suffix == '.py'))
