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

"""Which topics a replay reads, and what it says it assumed (other types, no stamp)."""

import pytest

from tskf_ros.bag.replay.cli import main
from tskf_ros.bag.replay.loop import replay

from ..helpers import scalar_bag


def run(capsys, *args):
    """Run replay_offline; return (exit status, stdout, stderr)."""
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize('msgtype,field', [
    ('sensor_msgs/msg/Temperature', 'temperature'),
    ('sensor_msgs/msg/FluidPressure', 'fluid_pressure'),
    ('sensor_msgs/msg/Range', 'range'),
])
def test_other_stamped_scalars_with_topic_flag(capsys, tmp_path, msgtype, field):
    bag = scalar_bag(tmp_path / 'bag', msgtype=msgtype, topic='/meter/value')
    code, out, err = run(capsys, bag, tmp_path / 'out', '--topic', '/meter/value')
    assert code == 0, err
    assert f'{msgtype}.{field}' in out
    if field == 'range':
        assert 'no variance field' in out
    reference = replay(scalar_bag(tmp_path / 'ref'), None, diagnostics=False)
    other = replay(bag, None, topic='/meter/value', diagnostics=False)
    est = [(t, m) for t, _, m in other.outputs if t.startswith('/estimate')]
    ref = [(t, m) for t, _, m in reference.outputs if t.startswith('/estimate')]
    assert [t for t, _ in est] == [t for t, _ in ref]
    assert all(a == b for (_, a), (_, b) in zip(est, ref))


def test_float64_uses_log_time_and_says_so_loudly(capsys, tmp_path):
    bag = scalar_bag(tmp_path / 'bag', msgtype='std_msgs/msg/Float64', topic='/power')
    code, out, err = run(capsys, bag, tmp_path / 'out')       # the only scalar topic
    assert code == 0, err
    assert 'WARNING' in err and 'log (receive) time' in err
    assert 'using /power' in out
    reference = replay(scalar_bag(tmp_path / 'ref'), None, diagnostics=False)
    other = replay(bag, None, diagnostics=False)
    assert [m.data[:2].tolist() for t, _, m in other.outputs if t == '/estimate/corrected'] == \
        [m.data[:2].tolist() for t, _, m in reference.outputs if t == '/estimate/corrected']
