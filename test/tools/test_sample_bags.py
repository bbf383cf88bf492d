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

"""Sample bags: regenerated from their README command they are the same; plots; layout."""

import copy
import json
from pathlib import Path
import re

from bag.helpers import flatten, one_line, usage_error
import pytest
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.cli import main as offline_main
from tskf_ros.tools import sample_bags
from tskf_ros.tools.plot_bag import main as plot_main

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / 'bags'


def readme_seed(name):
    """Return the seed of the README line that made bag `name`."""
    text = (BAGS / 'README.md').read_text()
    line = next(line for line in text.splitlines() if f'`{name}`' in line)
    return int(re.search(r'--seed (\d+)', line).group(1))


def messages(path):
    """
    Return (topic, type, log time, decoded message) of every message.

    Decoded, not bytes: numpy's results differ in the last bits from one CPU to another,
    so a regenerated bag need not have the same bytes (see assert_same_messages).
    """
    reader = BagReader(path)
    out = [(m.topic, m.msgtype, m.log_time_ns,
            deserialize_message(m.data, message_class(m.msgtype)))
           for m in reader.messages()]
    assert reader.damage is None
    return out


def assert_same_messages(got, want, rtol=1e-9):
    """
    Topics, types, log times, stamps, strings and counts exactly; floats to a relative rtol.

    numpy's SIMD paths differ between CPUs in the last bits (1e-11 relative seen on an
    AVX-512 machine for led_alignment), so floats are compared with a tolerance.
    """
    assert len(got) == len(want)
    for k, (g, w) in enumerate(zip(got, want)):
        assert g[:3] == w[:3], f'message {k}: {g[:3]} != {w[:3]}'
        fg, fw = flatten(g[3]), flatten(w[3])
        assert fg.keys() == fw.keys(), f'message {k}: fields differ'
        for key, a in fg.items():
            b = fw[key]
            if isinstance(a, float):
                assert a == pytest.approx(b, rel=rtol, abs=1e-300), f'message {k} {key}'
            else:
                assert a == b, f'message {k} {key}: {a!r} != {b!r}'


@pytest.mark.parametrize('name', ['owc_cai_td_1hz', 'led_alignment', 'led_pan_tilt', 'drogue'])
def test_regenerating_a_sample_bag_gives_the_same_messages(tmp_path, name):
    path = sample_bags.make(name, tmp_path, readme_seed(name))
    assert_same_messages(messages(path), messages(BAGS / name))


def test_the_message_comparison_catches_a_changed_value():
    got = [m for m in messages(BAGS / 'drogue') if m[0] == '/drogue/truth'][:3]
    want = [m[:3] + (copy.deepcopy(m[3]),) for m in got]
    assert_same_messages(got, want)
    want[2][3].position[1] *= 1 + 1e-6
    with pytest.raises(AssertionError, match='message 2'):
        assert_same_messages(got, want)


@pytest.mark.parametrize('name', list(sample_bags.SAMPLES))
def test_sample_bags_are_small_and_documented(name):
    size = sum(f.stat().st_size for f in (BAGS / name).iterdir())
    assert size < 5e6
    assert readme_seed(name) == sample_bags.DEFAULT_SEED


def test_cai_td_sample_has_exactly_the_gaps_of_td():
    reader = BagReader(BAGS / 'owc_cai_td_1hz')
    t = [(m.log_time_ns - sample_bags.START_S * 10**9) / 1e9
         for m in reader.messages(['/received_power'])]
    gaps = [(b, b - a) for a, b in zip(t, t[1:]) if b - a > 1.5]
    assert gaps == [(32.0, 2.0), (128.0, 2.0), (135.0, 4.0), (212.0, 3.0), (224.0, 6.0)]
    assert reader.topics['/true_angle'].count == 301


def test_plot_bag_writes_both_kinds(tmp_path, capsys):
    assert plot_main([str(BAGS / 'owc_cai_td_1hz'), '--out', str(tmp_path),
                      '--params-file', str(REPO / 'config' / 'owc_estimator.yaml')]) == 0
    assert plot_main([str(BAGS / 'led_alignment'), '--out', str(tmp_path)]) == 0
    for png in ('estimator.png', 'alignment.png'):
        assert (tmp_path / png).stat().st_size > 20_000
    assert plot_main([str(tmp_path / 'nope'), '--out', str(tmp_path)]) == 1
    assert 'no such bag' in capsys.readouterr().err


def test_plot_bag_on_an_offline_alignment_replay(tmp_path, capsys):
    out = tmp_path / 'led_aligned'
    assert offline_main(['--filter', 'alignment', str(BAGS / 'led_alignment'), str(out),
                         '--params-file', str(REPO / 'config' / 'alignment.yaml')]) == 0
    assert 'open loop' in capsys.readouterr().out
    reader = BagReader(out)
    assert {'/base_position_controller/commands', '/estimate/predicted',
            '/estimate/corrected', '/diagnostics', '/photodiode'} <= set(reader.topics)
    assert reader.topics['/base_position_controller/commands'].count == 381
    assert plot_main([str(out), '--out', str(tmp_path)]) == 0
    assert (tmp_path / 'alignment.png').stat().st_size > 20_000


def test_foxglove_layout_refers_to_topics_the_bags_have():
    layout = json.loads((REPO / 'config' / 'foxglove_layout.json').read_text())
    topics = set()
    for name in ('owc_cai_td_1hz', 'led_alignment', 'led_pan_tilt'):
        topics |= set(BagReader(BAGS / name).topics)
    topics |= {'/estimate/predicted', '/estimate/corrected', '/diagnostics'}
    for panel in layout['configById'].values():
        for path in panel.get('paths', []):
            assert path['value'].split('.')[0] in topics, path['value']


def test_make_sample_bags_refuses_bad_paths_and_seeds(tmp_path, capsys):
    (tmp_path / 'file').write_text('x')
    assert sample_bags.main(['--out', str(tmp_path / 'file'), '--only', 'led_alignment']) == 1
    one_line(capsys.readouterr().err, 'make_sample_bags: error: ', 'is not a directory')
    with pytest.raises(SystemExit) as exit_:
        sample_bags.main(['--out', str(tmp_path), '--seed', '-1'])
    assert exit_.value.code == 2
    usage_error(capsys.readouterr().err, 'make_sample_bags',
                '--seed must be in [0, 2**32), got -1')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['file']
