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
Every numeric option of every command line, any value: exit 0 or one line, never a traceback.

The tools' numeric options are listed here; test_the_list_is_the_help checks each list
against the options the tool's own --help shows (every option that takes a value is
either numeric here or listed as not), so that an option added later cannot be missed.
Each property test draws a value (any float's repr, any int, and the texts 1e308, -1e308,
nan, inf, -inf, 0, -0, -1, 1e9, 5e-324, 10**400) for one numeric option and runs the tool
in-process on a small case: it must exit 0 (stderr free: progress), or exit with its
documented status and one error line (after argparse's usage lines for status 2), never a
traceback.  play's and record's parsers are checked here; their nodes, which need rclpy,
take the accepted values in test/bag/test_play_record_numbers.py.  reproduce (40 s a run)
and demo (a ROS system) are parsed and checked, not run.  The bag tools' parameter
values (the estimator's parameter file, sweep's --set) are in
test/experiments/test_cli_properties.py.
"""

import contextlib
import io
from pathlib import Path
import re
import traceback
from typing import Callable, NamedTuple, Optional

from hypothesis import given, HealthCheck, settings, strategies as st
import pytest

from tskf_ros.bag import play_options, record_options, reindex
from tskf_ros.bag.replay import cli as replay_cli
from tskf_ros.experiments import (alignment_ablation, alignment_mc, demo, drogue, fit_noise,
                                  jump_covariance, lqg_comparison, reproduce, smoothing, sweep)
from tskf_ros.nodes import (alignment, led_link_simulator, power_meter_driver,
                            power_meter_simulator, timescale_estimator)
from tskf_ros.tools import console, foxglove_bridge, plot_bag, sample_bags

TEXTS = ['1e308', '-1e308', 'nan', 'inf', '-inf', '0', '-0', '-1', '1e9', '5e-324',
         str(10 ** 400), str(-10 ** 400), '1e-300', '0.5', '3']
VALUES = st.one_of(st.sampled_from(TEXTS), st.floats().map(repr), st.integers().map(str))


class Tool(NamedTuple):
    """A command line: how to run it on a small case and its options that take a value."""

    run: Callable[[list], Optional[int]]    # argv -> exit status (or raises SystemExit)
    base: Callable[[Path], list]            # the small case's arguments, in a folder
    numbers: tuple                          # its numeric options
    others: tuple                           # its other options that take a value
    statuses: tuple = (1,)                  # its documented failure statuses (besides 2)


def parse_play(argv: list) -> int:
    """Parse and check play's options as play does before it starts ROS; return 0."""
    parser = play_options.build_parser()
    play_options.player_options(parser, parser.parse_args(argv))
    return 0


def parse_record(argv: list) -> int:
    """Parse and check record's options as record does before it starts ROS; return 0."""
    parser = record_options.build_parser()
    opts = parser.parse_args(argv)
    record_options.check_options(parser, opts)
    record_options.recorder_options(opts)
    return 0


def node(main: Callable) -> Callable[[list], Optional[int]]:
    """Return a runner of a node's main (its argv starts with the program name)."""
    return lambda argv: main(['node', *argv])


NODE_OTHERS = ('--executor',)
TOOLS = {
    'play': Tool(parse_play, lambda d: [str(d / 'bag')],
                 ('--rate', '--clock', '--delay', '--playback-duration', '--playback-until-sec',
                  '--playback-until-nsec', '--start-offset', '--wait-for-all-acked'),
                 ('--storage', '--topics', '--regex', '--exclude-regex', '--exclude-topics',
                  '--qos-profile-overrides-path', '--remap')),
    'record': Tool(parse_record, lambda d: ['-o', str(d / 'rec'), '--topics', '/x'],
                   ('--polling-interval', '--max-bag-size', '--max-bag-duration',
                    '--flush-interval'),
                   ('--output', '--storage', '--topics', '--regex', '--exclude-regex',
                    '--exclude-topics', '--qos-profile-overrides-path', '--compression-mode',
                    '--compression-format', '--storage-preset-profile', '--node-name',
                    '--custom-data')),
    # reproduce's run takes 40 s on this machine: its values are parsed and checked here
    'reproduce': Tool(lambda argv: reproduce.parse_args(argv) and 0, lambda d: [
        '--out', str(d)],
        ('--seed', '--iterations', '--long-iterations', '--p12-step', '--td-dense-step'),
        ('--out', '--noise-scaling')),
    'make_sample_bags': Tool(sample_bags.main, lambda d: [
        '--out', str(d), '--only', 'led_alignment', '--overwrite'], ('--seed',),
        ('--out', '--only')),
    'alignment_mc': Tool(alignment_mc.main, lambda d: [
        '--runs', '2', '--steps', '3', '--noise-levels', '0.5', '--dropout-levels', '0.1',
        '--algorithms', 'ekf', '--workers', '1'],
        ('--runs', '--noise-levels', '--beta', '--steps', '--dt', '--seed', '--dropout',
         '--x2-0', '--cold-start', '--units-per-degree', '--x1-floor', '--fig9-beta',
         '--run-noise', '--dropout-levels', '--dropout-noise', '--dropout-beta', '--blocked',
         '--workers', '--axes'),
        ('--algorithms', '--controller', '--json', '--png', '--acquisition-png', '--fig8',
         '--fig9', '--pat-run', '--dropout-png', '--dropout-json', '--scheduler')),
    'alignment_ablation': Tool(alignment_ablation.main, lambda d: [
        '--runs', '2', '--steps', '3', '--noise-levels', '0.5', '--rows', 'ekf',
        '--workers', '1'],
        ('--runs', '--noise-levels', '--beta', '--steps', '--seed', '--workers'),
        ('--rows', '--json', '--markdown', '--png')),
    'lqg_comparison': Tool(lqg_comparison.main, lambda d: [
        '--runs', '2', '--steps', '3', '--betas', '1', '--workers', '1'],
        ('--runs', '--betas', '--noise', '--effort-noise', '--effort-beta', '--steps', '--dt',
         '--seed', '--ablation-beta', '--workers'), ('--json', '--png', '--scheduler')),
    'drogue': Tool(drogue.main, lambda d: ['--out', str(d), '--hours', '0.05'],
                   ('--seed', '--hours'), ('--out',)),
    'demo': Tool(lambda argv: demo.parse_args(argv) and 0, lambda d: [],
                 ('--duration', '--duration-scale', '--rate', '--seed', '--drop-probability',
                  '--domain-id', '--led-duration', '--led-time-factor', '--led-beta',
                  '--led-noise'),
                 ('--transition', '--blockage', '--led-algorithm', '--led-blockage', '--out',
                  '--reproduce')),
    'sweep': Tool(sweep.main, lambda d: [], ('--workers',),
                  ('--bags', '--params-file', '--set', '--topic', '--scheduler', '--out',
                   '--png')),
    'fit_noise': Tool(fit_noise.main, lambda d: [], (),
                      ('--params-file', '--topic', '--input-topic', '--out', '--json',
                       '--fix')),
    'replay_offline': Tool(replay_cli.main, lambda d: [], (),
                           ('--filter', '--params-file', '--topic', '--input-topic', '--npz')),
    'plot_bag': Tool(plot_bag.main, lambda d: [], (), ('--out', '--params-file', '--topic')),
    'reindex': Tool(reindex.main, lambda d: [], (), ('--output',)),
    'jump_covariance': Tool(jump_covariance.main, lambda d: [], (), ('--out',)),
    'smoothing': Tool(smoothing.main, lambda d: [], (), ('--bags', '--config', '--out',
                                                         '--only')),
    'timescale_estimator': Tool(node(timescale_estimator.main), lambda d: [], (), NODE_OTHERS),
    'power_meter_simulator': Tool(node(power_meter_simulator.main), lambda d: [], (),
                                  NODE_OTHERS),
    'power_meter_driver': Tool(node(power_meter_driver.main), lambda d: [], (), NODE_OTHERS),
    'led_link_simulator': Tool(node(led_link_simulator.main), lambda d: [], (), NODE_OTHERS),
    'alignment': Tool(node(alignment.main), lambda d: [], (), NODE_OTHERS),
    'foxglove_bridge': Tool(node(foxglove_bridge.main), lambda d: [], (), NODE_OTHERS),
}
NUMERIC = [(name, option) for name, tool in sorted(TOOLS.items()) for option in tool.numbers]
OPTION_LINE = re.compile(r'^  (-\S.*?)(?:  |$)')


class Outcome(NamedTuple):
    """How a run ended: its exit status, its stderr, and a traceback if one escaped."""

    code: int
    err: str
    escaped: str


def outcome(tool: Tool, argv: list) -> Outcome:
    """Run a tool in-process on argv; return its status, its stderr and what escaped."""
    err = io.StringIO()
    escaped = ''
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = tool.run(argv) or 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except Exception:   # noqa: B902 - what the user would see as a traceback
            code, escaped = -1, traceback.format_exc()
    return Outcome(code, err.getvalue(), escaped)


def value_options(tool: Tool) -> set:
    """Return the options that take a value, from the tool's --help (first long name)."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text), pytest.raises(SystemExit) as exit_:
        tool.run(['--help'])
    assert exit_.value.code == 0
    found = set()
    for line in text.getvalue().splitlines():
        match = OPTION_LINE.match(line)
        if not match:
            continue
        forms = [form.split(' ') for form in match.group(1).split(', ')]
        longs = [form[0] for form in forms if form[0].startswith('--')]
        if longs and any(len(form) > 1 for form in forms):
            found.add(longs[0])
    return found


@pytest.mark.parametrize('name', sorted(TOOLS))
def test_the_list_is_the_help(name):
    tool = TOOLS[name]
    assert value_options(tool) == set(tool.numbers) | set(tool.others)
    assert not set(tool.numbers) & set(tool.others)


def test_every_console_script_is_listed():
    assert set(console.TOOLS) <= set(TOOLS)


def check(tool: Tool, name: str, option: str, text: str, result: Outcome) -> None:
    """Assert exit 0, or a documented status with one error line; never a traceback."""
    where = (name, option, text, result.code, result.err[-2000:], result.escaped[-2000:])
    assert not result.escaped and 'Traceback' not in result.err, where
    if result.code == 0:
        return
    lines = [line for line in result.err.splitlines() if line.strip()]
    if result.code == 2 and lines and lines[0].startswith('usage:'):
        assert ': error: ' in lines[-1] and not any(': error: ' in x for x in lines[:-1]), where
        return
    assert result.code in (2,) + tool.statuses, where
    assert len([x for x in lines if not x.startswith('[')]) == 1, where   # [progress] free


@settings(max_examples=90, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(NUMERIC), text=VALUES)
def test_any_number_for_any_numeric_option(tmp_path_factory, case, text):
    name, option = case
    tool = TOOLS[name]
    folder = tmp_path_factory.mktemp(name)
    result = outcome(tool, [*tool.base(folder), f'{option}={text}'])
    check(tool, name, option, text, result)


@pytest.mark.parametrize('name,option', NUMERIC)
@pytest.mark.parametrize('text', ['1e308', '-1e308', 'nan', 'inf', '-inf', '0', '-1', '1e9',
                                  str(10 ** 400)])
def test_the_extremes_for_every_numeric_option(tmp_path, name, option, text):
    tool = TOOLS[name]
    check(tool, name, option, text, outcome(tool, [*tool.base(tmp_path), f'{option}={text}']))
