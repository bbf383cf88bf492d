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

"""Progress bars of the long runs: on a terminal's stderr only, off with --quiet."""

from pathlib import Path

from tskf_ros.bag.replay import cli as replay_cli
from tskf_ros.experiments import alignment_mc

REPO = Path(__file__).resolve().parents[2]


class Terminal:
    """A stderr that is a terminal (tqdm draws only on one), keeping what is written."""

    def __init__(self) -> None:
        self.text: list = []

    def isatty(self) -> bool:
        return True

    def write(self, s: str) -> int:
        self.text.append(s)
        return len(s)

    def flush(self) -> None:
        pass


def test_replay_offline_shows_the_messages_read(tmp_path, monkeypatch):
    term = Terminal()
    monkeypatch.setattr('sys.stderr', term)
    bag = REPO / 'bags' / 'owc_cai_td_1hz'
    assert replay_cli.main([str(bag), '--npz', str(tmp_path / 'a.npz')]) == 0
    shown = ''.join(term.text)
    assert 'replaying' in shown and '/589' in shown       # of every message of the bag
    term.text.clear()
    assert replay_cli.main([str(bag), '--npz', str(tmp_path / 'b.npz'), '-q']) == 0
    assert ''.join(term.text) == ''


def test_replay_offline_draws_nothing_when_stderr_is_not_a_terminal(tmp_path, capsys):
    bag = REPO / 'bags' / 'owc_cai_td_1hz'
    assert replay_cli.main([str(bag), '--npz', str(tmp_path / 'a.npz')]) == 0
    assert capsys.readouterr().err == ''


def test_alignment_mc_shows_its_points(monkeypatch):
    term = Terminal()
    monkeypatch.setattr('sys.stderr', term)
    assert alignment_mc.main(['--runs', '2', '--steps', '10', '--noise-levels', '0.5,1.5',
                              '--algorithms', 'ekf,hill_climbing,three_point']) == 0
    shown = ''.join(term.text)
    # 2 noise levels x 3 algorithms
    assert 'alignment_mc noise' in shown and '/6' in shown
