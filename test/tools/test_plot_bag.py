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

"""plot_bag on damaged bags and bad paths: what came before is plotted, errors in one line."""

import sys

from bag.helpers import BAGS, make_bag, one_line
from bag.test_reader import corrupt_bag

from tskf_ros.bag.reader import EXIT_DAMAGED
from tskf_ros.bag.replay.cli import main as replay_main
from tskf_ros.tools import plot_bag

import yaml


def test_plot_bag_on_a_truncated_bag_plots_what_came_before(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(60), chunk_size=2000)
    mcap = bag / 'bag.mcap'
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) * 6 // 10])
    code = plot_bag.main([str(bag), '--out', str(tmp_path / 'png')])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    one_line(err, 'plot_bag: bag damaged; plotted what came before: ', str(mcap),
             'truncated')
    assert (tmp_path / 'png' / 'estimator.png').is_file()


def test_plot_bag_when_nothing_before_the_damage_writes_nothing(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(10))
    mcap = bag / 'bag.mcap'
    mcap.write_bytes(mcap.read_bytes()[:40])
    code = plot_bag.main([str(bag), '--out', str(tmp_path / 'png')])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    one_line(err, 'plot_bag: bag damaged, nothing before the damage to plot: ', str(mcap),
             'the 0 message(s) before it')
    assert not (tmp_path / 'png').exists()


def test_plot_bag_refuses_a_missing_path(tmp_path, capsys):
    assert plot_bag.main([str(tmp_path / 'nope')]) == 1
    one_line(capsys.readouterr().err, 'plot_bag: error: ', 'no such bag')
    assert list(tmp_path.iterdir()) == []


def test_plot_bag_on_a_flipped_bit_reports_the_crc_damage(tmp_path, capsys):
    bag = corrupt_bag(tmp_path / 'bag')
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == EXIT_DAMAGED
    assert 'chunk CRC mismatch' in capsys.readouterr().err


def test_a_bag_of_an_unknown_package_type_is_refused_in_one_line(tmp_path, capsys):
    bag = make_bag(tmp_path / 'bag', range(5))
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['topics_with_message_count'][0]['topic_metadata'][
        'type'] = 'this/msg/X'
    meta.write_text(yaml.safe_dump(doc))
    assert plot_bag.main([str(bag), '--out', str(tmp_path / 'png')]) == 1
    out = capsys.readouterr()
    assert 'Zen' not in out.out
    one_line(out.err, 'plot_bag: error: ', 'this/msg/X')
    assert 'this' not in sys.modules


def _legends(monkeypatch):
    """Make plot_bag keep the legend entries of the figures it saves; return them."""
    seen = []
    save = plot_bag._save

    def keep(fig, path):
        seen.append([t.get_text() for ax in fig.axes if ax.get_legend()
                     for t in ax.get_legend().get_texts()])
        return save(fig, path)
    monkeypatch.setattr(plot_bag, '_save', keep)
    return seen


def test_plot_bag_draws_the_smoothed_estimate_when_the_bag_has_it(tmp_path, monkeypatch):
    params = str(BAGS.parent / 'config' / 'owc_estimator.yaml')
    for smooth in (True, False):
        out = tmp_path / f'est{smooth}'
        args = [str(BAGS / 'owc_cai_td_1hz'), str(out), '--params-file', params, '-q']
        assert replay_main(args + ['--smooth'] * smooth) == 0
        seen = _legends(monkeypatch)
        assert plot_bag.main([str(out), '--out', str(tmp_path / 'png'),
                              '--params-file', params]) == 0
        labels = [label for fig in seen for label in fig]
        assert ('smoothed x(t|T)' in labels) is smooth
        assert any(label.startswith('smoothed: RMS') for label in labels) is smooth
        assert 'corrected x(t|t)' in labels
