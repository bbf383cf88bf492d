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

"""One rule for every tool: no output is the input bag, a file of it, or a directory holding it."""

import os

import pytest

from tskf_ros.bag import reindex
from tskf_ros.bag.outputs import check_outputs, output_conflict, OutputInBagError
from tskf_ros.bag.replay.cli import main

from ..helpers import make_bag, one_line


@pytest.fixture
def bag(tmp_path):
    return make_bag(tmp_path / 'bag', range(5))


def files(path):
    return {p.name: p.read_bytes() for p in path.iterdir()}


def test_the_rule(bag, tmp_path):
    mcap = bag / 'bag.mcap'
    for out in (bag, mcap, bag / 'metadata.yaml', bag / 'new.json', bag / 'sub' / 'x',
                tmp_path, tmp_path.parent):
        assert output_conflict(out, bag), out
        assert output_conflict(out, mcap), out       # the bag named by its .mcap file
    (tmp_path / 'link').symlink_to(mcap)
    os.link(mcap, tmp_path / 'hard')
    assert 'input bag' in output_conflict(tmp_path / 'link', bag)
    assert 'a link' in output_conflict(tmp_path / 'hard', bag)
    for out in (tmp_path / 'other.json', tmp_path / 'bag_estimated', tmp_path / 'bag2'):
        assert output_conflict(out, bag) is None, out
    # a bare .mcap file (no metadata.yaml beside it): its directory may take outputs
    bare = tmp_path / 'bare'
    bare.mkdir()
    os.link(mcap, bare / 'x.mcap')
    assert output_conflict(bare / 'x.mcap', bare / 'x.mcap')
    assert output_conflict(bare / 'out.json', bare / 'x.mcap') is None
    check_outputs([None, tmp_path / 'fine.json'], [bag, mcap])
    with pytest.raises(OutputInBagError, match='input bag'):
        check_outputs([tmp_path / 'fine.json', bag / 'x'], [bag])


def test_replay_offline_arrays_may_not_go_into_the_bag(bag, capsys):
    before = files(bag)
    for target in (bag / 'bag.mcap', bag / 'out.npz'):
        assert main([str(bag), '--npz', str(target), '--overwrite']) == 1
        one_line(capsys.readouterr().err, 'replay_offline: error: ', 'input bag')
        assert files(bag) == before


def test_replay_offline_into_a_symlink_of_its_input_is_refused(bag, tmp_path, capsys):
    (tmp_path / 'alias').symlink_to(bag)
    before = files(bag)
    assert main([str(bag), str(tmp_path / 'alias'), '--overwrite']) == 1
    one_line(capsys.readouterr().err, 'replay_offline: error: ', 'input bag')
    assert files(bag) == before


def test_reindex_output_may_not_be_inside_its_input(bag, capsys):
    before = files(bag)
    assert reindex.main([str(bag), '-o', str(bag / 'inner')]) == 1
    one_line(capsys.readouterr().err, 'reindex: error: ', 'input bag')
    assert files(bag) == before
