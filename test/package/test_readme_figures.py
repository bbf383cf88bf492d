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
"""The README quotes its measured figures from docs/readme_figures.json, as measured."""

import datetime
from pathlib import Path
import re
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parent.parent.parent
sys.path.insert(0, str(REPO / 'bench'))

import readme_figures  # noqa: E402, I100 (bench/, not a package)

REGENERATE = 'python bench/readme_figures.py'


def test_every_figure_the_readme_quotes_is_the_jsons():
    readme = readme_figures.README.read_text()
    figures = readme_figures.load()
    assert readme_figures.quote(readme, figures) == readme, \
        f'README.md differs from {readme_figures.FIGURES.name}: run {REGENERATE}'


def test_the_readme_quotes_the_test_count_and_the_venv_with_their_dates():
    names = {(m['name'], m['field']) for m in
             readme_figures.MARKER.finditer(readme_figures.README.read_text())}
    for name in ('tests', 'venv'):
        assert {(name, None), (name, 'measured')} <= names, name


def test_the_readme_has_no_unquoted_stale_figure():
    # the figures this page once gave by hand, and that went stale
    text = readme_figures.MARKER.sub('', readme_figures.README.read_text())
    for stale in ('1122 tests', '640 MB'):
        assert stale not in text


@pytest.mark.parametrize('name', sorted(readme_figures.load()))
def test_each_figure_says_how_and_when_it_was_measured(name):
    entry = readme_figures.load()[name]
    datetime.date.fromisoformat(entry['measured'])
    assert entry['command'] and entry['load']
    groups = re.compile(entry['pattern'], re.MULTILINE).groupindex
    # the format uses the pattern's groups, and makes the text quoted (from sample values)
    sample = {group: 1 for group in groups}
    entry['format'].format(**sample)
    assert set(re.findall(r'\{(\w+)', entry['format'])) <= set(groups), name


def test_measuring_takes_the_figure_out_of_the_commands_output(tmp_path, monkeypatch):
    entry = {'command': "printf 'noise\\n42 tests collected in 3s\\n'",
             'pattern': r'^(?P<n>\d+) tests collected', 'format': '{n}', 'text': '1',
             'measured': '2000-01-01', 'load': '0'}
    new = readme_figures.measure('tests', entry)
    assert new['text'] == '42' and new['measured'] == datetime.date.today().isoformat()
    with pytest.raises(readme_figures.FigureError, match='is not in the output'):
        readme_figures.measure('tests', {**entry, 'command': 'echo nothing'})


def test_quoting_rewrites_the_markers_only():
    figures = {'tests': {'text': '42', 'measured': '2026-01-02'}}
    before = 'the <!--fig:tests-->7<!--/fig--> tests (<!--fig:tests.measured-->x<!--/fig-->), 7'
    assert readme_figures.quote(before, figures) == (
        'the <!--fig:tests-->42<!--/fig--> tests (<!--fig:tests.measured-->2026-01-02'
        '<!--/fig-->), 7')
    with pytest.raises(readme_figures.FigureError, match='does not have'):
        readme_figures.quote('<!--fig:nothing-->1<!--/fig-->', figures)


@pytest.mark.slow
def test_the_test_count_is_within_a_tenth_of_the_suites():
    # collecting is cheap (seconds); the count the README gives must not drift far
    out = subprocess.run([sys.executable, '-m', 'pytest', '--collect-only', '-q',
                          '-p', 'no:cacheprovider'], cwd=REPO, capture_output=True,
                         text=True, timeout=600, check=False).stdout
    collected = int(re.search(r'^(\d+) tests collected', out, re.MULTILINE)[1])
    quoted = int(readme_figures.load()['tests']['text'])
    assert abs(collected - quoted) <= collected / 10, \
        f'{collected} tests, the README says {quoted}: run {REGENERATE} --measure tests'
