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

"""Symlink loops and Ctrl-C in the bag tools: one line, a fixed exit status, nothing left."""

import re
import shutil

import pytest

from tskf_ros.bag import player
from tskf_ros.bag.bag_errors import BagNotFoundError, EXIT_INTERRUPTED, resolved
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay import adapters, cli
from tskf_ros.bag.replay.gathered import Gathered
from tskf_ros.tools import plot_bag

from .helpers import BAGS, mcap_file, one_line

LOOP = 'a symlink loop (too many levels of symbolic links)'


def looped_bag(tmp_path):
    """Return (a bag whose storage file is a symlink to itself, a bag path that is a loop)."""
    bag = tmp_path / 'bag'
    shutil.copytree(BAGS / 'owc_cai_td_1hz', bag)
    storage = mcap_file(bag)
    storage.unlink()
    storage.symlink_to(storage.name)
    loop = tmp_path / 'loop'
    loop.symlink_to('loop')
    return bag, storage, loop


def test_the_reader_says_symlink_loop_for_the_bag_and_for_its_storage_file(tmp_path):
    bag, storage, loop = looped_bag(tmp_path)
    with pytest.raises(BagNotFoundError) as info:
        BagReader(bag)
    assert str(info.value).startswith(f'{storage}: {LOOP}')
    assert '\n' not in str(info.value)
    with pytest.raises(BagNotFoundError, match=f'^{re.escape(f"{loop}: {LOOP}")}$'):
        BagReader(loop)
    with pytest.raises(BagNotFoundError) as info:
        resolved(loop / 'x')
    assert str(info.value).startswith(f'{loop / "x"}: {LOOP}')


@pytest.mark.parametrize('which', ['storage', 'bag'])
def test_the_tools_say_symlink_loop_in_one_line(tmp_path, capsys, which):
    bag, storage, loop = looped_bag(tmp_path)
    path = bag if which == 'storage' else loop
    where = storage if which == 'storage' else loop
    out = tmp_path / 'out'
    for prog, run in (('replay_offline', lambda: cli.main([str(path), str(out), '-q'])),
                      ('replay_offline', lambda: cli.main([str(path), '--npz', str(out)])),
                      ('plot_bag', lambda: plot_bag.main([str(path), '--out', str(out)])),
                      ('play', lambda: player.main(['play', str(path)]))):
        capsys.readouterr()
        assert run() == 1, prog
        one_line(capsys.readouterr().err, f'{prog}: error: {where}: {LOOP}')
        assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'loop'], prog


def interrupt_after(monkeypatch, calls):
    """Make the offline estimator's n-th message raise KeyboardInterrupt (a Ctrl-C)."""
    count = [0]

    def counted(real):
        def call(self, *args):
            count[0] += 1
            if count[0] == calls:
                raise KeyboardInterrupt
            return real(self, *args)
        return call
    # one sample at a time, or gathered into runs (the estimator's replay)
    monkeypatch.setattr(adapters.OfflineEstimator, 'process',
                        counted(adapters.OfflineEstimator.process))
    monkeypatch.setattr(Gathered, 'add', counted(Gathered.add))


def console(module):
    """Run a command's console script; return its SystemExit (a Ctrl-C escaping fails)."""
    try:
        module.console_main()
    except SystemExit as exc:
        return exc
    except KeyboardInterrupt:
        pytest.fail('the KeyboardInterrupt escaped the command (a traceback)')
    pytest.fail('the command did not exit')


@pytest.mark.parametrize('output', ['bag', 'npz'])
def test_ctrl_c_in_replay_offline_is_one_line_exit_130_nothing_written(tmp_path, monkeypatch,
                                                                       capsys, output):
    interrupt_after(monkeypatch, 200)
    out = tmp_path / 'out'
    argv = [str(BAGS / 'owc_ge_1khz'), str(out)] if output == 'bag' else \
        [str(BAGS / 'owc_ge_1khz'), '--npz', str(out)]
    monkeypatch.setattr('sys.argv', ['replay_offline'] + argv + ['-q'])
    exit_ = console(cli)
    assert exit_.code == EXIT_INTERRUPTED
    one_line(capsys.readouterr().err, 'replay_offline: interrupted; no unfinished output is '
             'kept')
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_in_plot_bag_is_one_line_exit_130_nothing_written(tmp_path, monkeypatch,
                                                                 capsys):
    interrupt_after(monkeypatch, 200)
    out = tmp_path / 'plots'
    monkeypatch.setattr('sys.argv', ['plot_bag', str(BAGS / 'owc_cai_td_1hz'), '--out',
                                     str(out)])
    exit_ = console(plot_bag)
    assert exit_.code == EXIT_INTERRUPTED
    assert capsys.readouterr().err == 'plot_bag: interrupted; no unfinished output is kept\n'
    assert not out.exists() or list(out.iterdir()) == []


def test_ctrl_c_while_plot_bag_saves_leaves_no_partial_png(tmp_path, monkeypatch, capsys):
    def savefig(self, path, **kwargs):
        path.write_bytes(b'\x89PNG half')     # what a save cut short leaves
        raise KeyboardInterrupt
    monkeypatch.setattr(plot_bag.plt.Figure, 'savefig', savefig)
    out = tmp_path / 'plots'
    monkeypatch.setattr('sys.argv', ['plot_bag', str(BAGS / 'owc_cai_td_1hz'), '--out',
                                     str(out)])
    exit_ = console(plot_bag)
    assert exit_.code == EXIT_INTERRUPTED
    assert list(out.iterdir()) == []
