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

"""play's and record's numeric options: any value is played, recorded or refused in one line."""

import math
import subprocess
import sys

from hypothesis import example, given, HealthCheck, settings, strategies as st
import pytest

from tskf_ros.bag import play_options, player, record_options, recorder
from tskf_ros.bag.bag_options import OptionError
from tskf_ros.bag.player import Player, PlayerError

from .helpers import make_bag, NS, TIMEOUT, usage_error

# s: the longest time of whole seconds in int64 ns
INT64_S = (2 ** 63 - 1) // NS
SETTINGS = settings(derandomize=True, max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
PLAY_FLOATS = ('--rate', '--start-offset', '--delay', '--playback-duration',
               '--playback-until-sec', '--clock')
EXTREMES = ('1e308', '-1e308', 'nan', 'inf', '-inf')
numbers = st.one_of(st.floats(), st.sampled_from([1e308, -1e308, 5e-324, 0.0, -0.0,
                                                  9.3e9, 9.2e9, 1e-300]))


def parse_play(argv, capsys):
    """Return the Player's kwargs, or None after checking a one-line usage error (exit 2)."""
    parser = play_options.build_parser()
    capsys.readouterr()
    try:
        return play_options.player_options(parser, parser.parse_args(argv))
    except SystemExit as exc:
        assert exc.code == 2
        err = capsys.readouterr().err
        assert 'Traceback' not in err
        usage_error(err, 'play', err.splitlines()[-1].partition('error: ')[2])
        return None


@pytest.fixture(scope='module')
def small_bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp('numbers') / 'bag', [0.0, 0.5, 1.0, 30.0])


@pytest.mark.parametrize('flag', PLAY_FLOATS[1:])
@pytest.mark.parametrize('value', EXTREMES)
def test_play_refuses_extreme_times_in_one_line(small_bag, capsys, flag, value):
    number = float(value)
    if flag == '--clock':
        if number == 1e308:
            pytest.skip('a /clock at 1e308 Hz is published at every tick')
        text = f'--clock must be a finite number >= 0, got {number}'
    elif number < 0 and flag in ('--playback-duration', '--playback-until-sec'):
        pytest.skip('negative: no limit (rosbag2)')
    else:
        text = (f'{flag} must be a finite number >= 0 and at most {INT64_S} s (int64 '
                f'nanoseconds), got {number}')
    with pytest.raises(SystemExit) as exit_:
        player.main(['play', str(small_bag), f'{flag}={value}'])
    assert exit_.value.code == 2
    usage_error(capsys.readouterr().err, 'play', text)


def test_play_at_a_rate_of_1e308_plays_everything_at_once(small_bag):
    proc = subprocess.run([sys.executable, '-m', 'tskf_ros.bag.player', str(small_bag),
                           '--rate', '1e308', '--clock', '1e308', '--wait-for-all-acked', '0'],
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.splitlines()[-1] == 'play: published /received_power 4'
    assert 'Traceback' not in proc.stderr


def test_the_bag_time_at_a_rate_of_1e308_is_finite(small_bag, ros_context):
    node = Player(small_bag, rate=1e308, clock_hz=1e308, context=ros_context)
    try:
        assert node.bag_now() >= node.bag_start
        while not node.done.done():
            node._tick()
        node._publish_clock(node.bag_now(), 0, force=True)
        assert node.published == {'/received_power': 4}
    finally:
        node.destroy_node()


@pytest.mark.parametrize('kwargs', [{'start_offset': 1e308}, {'delay': 1e308},
                                    {'playback_duration': 1e308}, {'clock_hz': 1e-308},
                                    {'delay': math.nan}, {'delay': -1.0}])
def test_the_player_refuses_extreme_times_with_a_player_error(small_bag, ros_context, kwargs):
    with pytest.raises(PlayerError) as info:
        Player(small_bag, context=ros_context, **kwargs)
    assert '\n' not in str(info.value) and 'must be a finite number' in str(info.value)


@SETTINGS
@given(flag=st.sampled_from(PLAY_FLOATS + ('--playback-until-nsec',)),
       value=st.one_of(numbers, st.integers(), st.sampled_from([10 ** 400, -10 ** 400])))
@example(flag='--rate', value=1e308)
@example(flag='--clock', value=5e-324)
@example(flag='--playback-until-nsec', value=2 ** 63)
@example(flag='--playback-until-nsec', value=2 ** 63 - 1)
def test_any_number_for_a_play_option_plays_or_is_one_line(small_bag, ros_context, capsys,
                                                           flag, value):
    kwargs = parse_play([str(small_bag), f'{flag}={value!r}'], capsys)
    if kwargs is None:
        return
    try:
        node = Player(small_bag, context=ros_context, **kwargs)
    except PlayerError as exc:          # e.g. an offset past the end of the bag
        assert '\n' not in str(exc)
        return
    try:
        for _ in range(3):
            node._tick()
            node._publish_clock(node.bag_now(), 0, force=True)
    finally:
        node.destroy_node()


def test_wait_for_all_acked_is_a_count_of_ms(small_bag, capsys):
    assert play_options.build_parser().parse_args([str(small_bag)]).wait_for_all_acked == \
        play_options.WAIT_ACKED_MS
    assert parse_play([str(small_bag), '--wait-for-all-acked', '0'], capsys) is not None
    assert parse_play([str(small_bag), '--wait-for-all-acked', '-1'], capsys) is None
    assert parse_play([str(small_bag), '--wait-for-all-acked', str(10 ** 400)], capsys) is None
    assert parse_play([str(small_bag), '--wait-for-all-acked', '1e308'], capsys) is None


# -- record -------------------------------------------------------------------------------

def parse_record(argv, capsys):
    """Return the Recorder's kwargs, or None after checking a one-line usage error."""
    parser = record_options.build_parser()
    capsys.readouterr()
    try:
        opts = parser.parse_args(argv)
        record_options.check_options(parser, opts)
        return record_options.recorder_options(opts)
    except SystemExit as exc:
        assert exc.code == 2
        err = capsys.readouterr().err
        assert 'Traceback' not in err
        usage_error(err, 'record', err.splitlines()[-1].partition('error: ')[2])
        return None


def test_record_flush_interval_1e308_is_one_line_and_leaves_nothing(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        recorder.main(['record', '-o', str(tmp_path / 'bag'), '--topics', '/x',
                       '--flush-interval', '1e308'])
    assert exit_.value.code == 2
    assert 'Traceback' not in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_the_recorder_refuses_1e308_before_making_anything(tmp_path, ros_context):
    for kwargs in ({'flush_interval': 1e308}, {'max_bag_duration': 1e308},
                   {'discovery_period': 1e308}, {'flush_interval': math.inf}):
        with pytest.raises(OptionError) as info:
            recorder.Recorder(tmp_path / 'bag', topics=['/x'], context=ros_context, **kwargs)
        assert '\n' not in str(info.value)
        assert list(tmp_path.iterdir()) == [], 'no .partial directory is left behind'


@SETTINGS
@given(flag=st.sampled_from(['--flush-interval', '--max-bag-duration', '--polling-interval',
                             '--max-bag-size']),
       value=st.one_of(numbers, st.integers(), st.sampled_from([10 ** 400, -10 ** 400])))
@example(flag='--flush-interval', value=1e308)
@example(flag='--max-bag-duration', value=10 ** 400)
@example(flag='--polling-interval', value=10 ** 400)
def test_any_number_for_a_record_option_records_or_is_one_line(tmp_path_factory, ros_context,
                                                               capsys, flag, value):
    top = tmp_path_factory.mktemp('rec')
    kwargs = parse_record(['-o', str(top / 'bag'), '--topics', '/x:std_msgs/msg/String',
                           f'{flag}={value}'], capsys)
    if kwargs is not None:
        rec = recorder.Recorder(top / 'bag', context=ros_context, **kwargs)
        rec.flush()
        rec.destroy_node()
        assert [p.name for p in top.iterdir()] == ['bag']
    else:
        assert list(top.iterdir()) == []
