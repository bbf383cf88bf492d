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
Property tests of the offline tools' command lines: any number, one outcome, never a traceback.

Every numeric input of fit_noise, sweep, replay_offline and plot_bag (the estimator's
numeric parameters, through a parameter file or --set, and sweep's --workers) is drawn
from all floats (nan, +-inf, +-1e308, subnormals, negatives); each run, in-process, must
end in exit 0 (or another documented status) with at most one line on stderr, never a
Python traceback.  A value outside the node's declared range is refused in that line.
"""

from pathlib import Path

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest
from rclpy.serialization import serialize_message

from tskf_ros.bag.replay import cli as replay_cli
from tskf_ros.bag.writer import BagWriter
from tskf_ros.experiments import fit_noise, sweep
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import NODE_NAME
from tskf_ros.messages.parameter_schema import load_schema
from tskf_ros.tools import plot_bag

# the estimator's double parameters with a range, from its schema (what the node declares)
RANGES = {spec.name: spec.closed_range() for spec in load_schema(NODE_NAME).parameters.values()
          if spec.type_name == 'double' and spec.closed_range() is not None
          and not spec.read_only}
NAMES = sorted(RANGES)
SPECIAL = [float('nan'), float('inf'), -float('inf'), 1e308, -1e308, 0.0, -0.0, 5e-324,
           -1.0, 1e-300]
VALUES = st.one_of(st.sampled_from(SPECIAL), st.floats(allow_nan=True, allow_infinity=True))
# documented exit statuses: done, refused, damaged input, no usable fit, row errors
STATUSES = {0, 1, 3, 4, 5}
PARAMS_HEAD = """/**/timescale_estimator:
  ros__parameters:
    nonpositive_is_gap: false
"""
SLOW = settings(max_examples=25, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def yaml_float(value: float) -> str:
    """Return a float as the YAML of a ROS parameter file writes it (.nan, .inf)."""
    if np.isnan(value):
        return '.nan'
    if np.isinf(value):
        return '.inf' if value > 0 else '-.inf'
    return repr(value)


@pytest.fixture(scope='module')
def small(tmp_path_factory):
    """Write a 40-sample bag at 1 Hz near 300 mW (model (3)'s output); return its folder."""
    d = tmp_path_factory.mktemp('cli')
    rng = np.random.default_rng(4)
    with BagWriter(d / 'bag') as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(40):
            ns = 1_700_000_000_000_000_000 + k * 1_000_000_000
            w.write('/received_power', ns, serialize_message(conversions.power_to_msg(
                ns, 300.0 + rng.normal(0.0, 1.0), 0.0)))
    return d


def params_with(directory: Path, name: str, value: float) -> Path:
    """Write a parameter file setting name: value; return its path."""
    path = directory / 'p.yaml'
    path.write_text(PARAMS_HEAD + f'    {name}: {yaml_float(value)}\n')
    return path


def check(capsys, code: int, name: str, value: float) -> None:
    """Assert a documented status, at most one line on stderr, and no traceback."""
    err = capsys.readouterr().err       # (stdout: what the tool did, free)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code in STATUSES and len(lines) <= 1 and 'Traceback' not in err, (
        name, value, code, err)
    lo, hi = RANGES[name]
    if not lo <= value <= hi:
        assert code == 1 and name in lines[0], (name, value, lines)


@SLOW
@given(name=st.sampled_from(NAMES), value=VALUES)
def test_fit_noise_any_parameter_value(small, tmp_path, capsys, name, value):
    params = params_with(tmp_path, name, value)
    code = fit_noise.main([str(small / 'bag'), '--params-file', str(params), '--fix', 'Q',
                           '--json', str(tmp_path / 'f.json'), '-q'])
    check(capsys, code, name, value)


@SLOW
@given(name=st.sampled_from(NAMES), value=VALUES)
def test_replay_offline_any_parameter_value(small, tmp_path, capsys, name, value):
    params = params_with(tmp_path, name, value)
    code = replay_cli.main([str(small / 'bag'), '--npz', str(tmp_path / 'a.npz'),
                            '--params-file', str(params), '--overwrite', '-q'])
    check(capsys, code, name, value)


@SLOW
@given(name=st.sampled_from(NAMES), value=VALUES)
def test_sweep_any_set_value(small, tmp_path, capsys, name, value):
    code = sweep.main(['--bags', str(small / 'bag'), '--set', f'{name}={value!r}',
                       '--workers', '0', '--out', str(tmp_path / 't.csv'), '--no-resume',
                       '--no-progress'])
    check(capsys, code, name, value)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(workers=st.integers().filter(lambda w: not 0 <= w <= sweep.MAX_WORKERS))
def test_sweep_any_worker_count(small, tmp_path, capsys, workers):
    # outside [0, MAX_WORKERS]: argparse's usage line and one error line, exit 2
    with pytest.raises(SystemExit) as exit_:
        sweep.main(['--bags', str(small / 'bag'), '--workers', str(workers), '--out',
                    str(tmp_path / 't.csv')])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert exit_.value.code == 2 and 'Traceback' not in err
    assert lines[0].startswith('usage:') and lines[-1].startswith('sweep: error: --workers')


@settings(max_examples=12, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(NAMES), value=VALUES)
def test_plot_bag_any_parameter_value(small, tmp_path, capsys, name, value):
    params = params_with(tmp_path, name, value)
    code = plot_bag.main([str(small / 'bag'), '--out', str(tmp_path / 'plots'),
                          '--params-file', str(params)])
    check(capsys, code, name, value)
