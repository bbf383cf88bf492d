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

"""The docs build (-W -n), show every node's parameters, interface and tasks, mention no issues."""

import html
import importlib.util
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys

from documented_commands import documentation
import pytest

from tskf_ros.messages.interface_spec import DiagnosticTask, IN, OUT
from tskf_ros.messages.node_interfaces import INTERFACES
from tskf_ros.messages.parameter_schema import load_schema

REPO_ROOT = Path(__file__).resolve().parents[2]
DOC = REPO_ROOT / 'doc'
# the project rule: no user-facing text mentions issues (of a tracker or otherwise)
ISSUE = re.compile(r'\bissues?\b', re.IGNORECASE)
SMART_QUOTES = {'\u2018': "'", '\u2019': "'", '\u201c': '"', '\u201d': '"',
                '\u2014': '---', '\u2013': '--', '\u2026': '...'}


@pytest.fixture(scope='module')
def site(tmp_path_factory) -> Path:
    """Build the documentation once, as ./run docs does; return the HTML folder."""
    # -W warnings are errors, -n every cross-reference must resolve, --keep-going reports
    # all of them at once
    tmp_path = tmp_path_factory.mktemp('docs')
    out = tmp_path / 'html'
    build = subprocess.run(
        [sys.executable, '-m', 'sphinx', '-W', '-n', '--keep-going', '-q', '-b', 'html',
         '-d', str(tmp_path / 'doctrees'), str(DOC), str(out)],
        capture_output=True, text=True, timeout=600, check=False)
    assert build.returncode == 0, \
        f'sphinx-build failed (exit {build.returncode}):\n{build.stderr}{build.stdout}'
    return out


# the generated tables of the pages, by their css class (doc/_ext)
TABLE_CLASSES = ('parameter-table', 'topic-table', 'service-table', 'diagnostic-table',
                 'node-overview', 'diagnostic-overview', 'diagnostic-levels')


def tables(page: str) -> dict:
    """Return {css class: count} of a page's tables, every table under the key 'all'."""
    counts = {name: len(re.findall(rf'<table[^>]*class="[^"]*\b{name}\b', page))
              for name in TABLE_CLASSES}
    return {'all': page.count('<table'), **counts}


def pages(html_root: Path) -> list:
    """Return the documentation pages of an HTML build, relative (no index or search page)."""
    return sorted(str(path.relative_to(html_root)) for path in html_root.rglob('*.html')
                  if path.name not in ('genindex.html', 'search.html', 'py-modindex.html')
                  and not {'_static', '_sources', '_modules'} & set(path.parts))


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec('rosdoc2') is None,
                    reason='rosdoc2 is not installed (docs.ros.org runs it on the package)')
def test_rosdoc2_builds_every_page_with_every_table(site, tmp_path):
    # rosdoc2 on a copy of the package, as docs.ros.org runs it (no ROS_DISTRO: offline)
    package = tmp_path / 'src' / 'tskf_ros'
    shutil.copytree(REPO_ROOT, package, symlinks=True, ignore=shutil.ignore_patterns(
        '.git', '.venv', '.pytest_cache', '.mypy_cache', '_build', 'results', 'build',
        'install', 'log', '__pycache__', '*.egg-info'))
    env = {k: v for k, v in os.environ.items() if k != 'ROS_DISTRO'}
    build = subprocess.run(
        [sys.executable, '-c', 'import sys; from rosdoc2.main import main; sys.exit(main())',
         'build', '--package-path', str(package), '--output-directory', str(tmp_path / 'out'),
         '--cross-reference-directory', str(tmp_path / 'xref'),
         '--doc-build-directory', str(tmp_path / 'docs_build')],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1800)
    log = build.stdout + build.stderr
    assert build.returncode == 0, log[-20000:]
    for refused in ('not supported', 'Unknown directive', 'image file not readable',
                    'multiple files found', 'conf.py for package'):
        assert refused not in log, [line for line in log.splitlines() if refused in line]
    # every page of ./run docs, below doc/ there, with the same tables
    ours = tmp_path / 'out' / 'tskf_ros' / 'doc'
    missing = [name for name in pages(site) if not (ours / name).is_file()]
    assert not missing, f'pages rosdoc2 does not build: {missing}'
    differ = {name: (tables((site / name).read_text()), tables((ours / name).read_text()))
              for name in pages(site)
              if tables((site / name).read_text()) != tables((ours / name).read_text())}
    assert not differ, differ
    node_tables = tables((ours / 'nodes' / 'timescale_estimator.html').read_text())
    assert node_tables['parameter-table'] and node_tables['topic-table']
    # the README (rosdoc2's front page) shows its figures
    readme = (tmp_path / 'out' / 'tskf_ros' / '__README.html').read_text()
    images = re.findall(r'<img [^>]*src="([^"]+)"', readme)
    assert images and all((tmp_path / 'out' / 'tskf_ros' / src).is_file() for src in images)


def test_the_documentation_builds_without_a_warning(site):
    assert (site / 'index.html').is_file()
    # every design draft is a page (the glob toctree picks up new ones)
    drafts = sorted(path.stem for path in (DOC / 'design').glob('*.md'))
    assert drafts, 'doc/design/ holds no draft'
    missing = [name for name in drafts if not (site / 'design' / f'{name}.html').is_file()]
    assert not missing, f'design drafts without a page: {missing}'


def test_every_node_page_shows_its_parameters_and_interface(site):
    out = site
    # every node page shows its schema's parameter table, row for row, cell for cell
    # (test/nodes/test_parameter_schema.py checks the running nodes against the schemas)
    for schema in sorted((REPO_ROOT / 'config' / 'schema').glob('*.yaml')):
        page = (out / 'nodes' / f'{schema.stem}.html').read_text()
        rows = table_rows(page, 'parameter-table', 6)
        want = [(r.name, r.type_name, r.default, r.constraints, 'yes' if r.read_only else '',
                 r.description) for r in load_schema(schema.stem).table_rows()]
        assert rows == want, schema.stem
    # and its declared topics, services and diagnostic tasks (node_interfaces; checked
    # against the running nodes by test/nodes/test_node_interfaces.py)
    for name, declared in INTERFACES.items():
        page = (out / 'nodes' / f'{name}.html').read_text()
        # (a type a parameter names reads '<default type> (default; ...)')
        topics = [(row[0], row[1], row[2].split(' ')[0])
                  for row in table_rows(page, 'topic-table', 5)]
        assert topics[:-1] == [(t.name, t.direction, t.msg_type) for t in declared.topics], name
        services = [row[:2] for row in table_rows(page, 'service-table', 3)]
        assert services[:len(declared.services)] == [(s.name, s.srv_type)
                                                     for s in declared.services], name
        shown = task_sections(page)
        assert [status for statuses, _ in shown for status in statuses] == \
            declared.status_names(), name
        for (_, levels), task in zip(shown, declared.diagnostics):
            assert levels == level_rows(task), f'{name}: {task.name}'


def test_the_nodes_overview_shows_every_declared_topic_and_service(site):
    # doc/nodes/index.md: one row per node, its topics in and out and its services, each
    # with its type (a topic the node gains is declared, or test_node_interfaces fails)
    rows = table_cells((site / 'nodes' / 'index.html').read_text(), 'node-overview', 5)
    assert [plain(row[0]) for row in rows] == list(INTERFACES)
    for row, declared in zip(rows, INTERFACES.values()):
        assert declared.purpose and plain(row[1]) == declared.purpose, declared.node
        for cell, direction in ((row[2], IN), (row[3], OUT)):
            items = [plain(item) for item in re.findall(r'<li>(.*?)</li>', cell, re.DOTALL)]
            topics = [t for t in declared.topics if t.direction == direction]
            assert [item.split(' (')[0] for item in items] == [t.name for t in topics], \
                f'{declared.node} {direction}'
            for item, topic in zip(items, topics):
                assert item.startswith(f'{topic.name} ({topic.msg_type}'), item
        shown = [plain(code) for code in re.findall(r'<code.*?</code>', row[4], re.DOTALL)]
        assert shown == [s.name for s in declared.services], declared.node
        assert all(s.srv_type in plain(row[4]) for s in declared.services), declared.node


def test_the_diagnostics_page_shows_every_task_and_its_levels(site):
    page = (site / 'diagnostics.html').read_text()
    # the overview: every node's statuses in publishing order, their levels and summary
    want = [(name, status, ', '.join(task.level_names()), task.summary.replace('`', ''))
            for name, declared in INTERFACES.items()
            for task, status in zip(declared.diagnostics, declared.status_names())]
    assert table_rows(page, 'diagnostic-overview', 4) == want
    # and a level table of every task under its status names, each status once (a task
    # the page's sections do not name fails here)
    tasks = {status: task for declared in INTERFACES.values()
             for task, status in zip(declared.diagnostics, declared.status_names())}
    seen = []
    for statuses, levels in task_sections(page):
        for status in statuses:
            assert levels == level_rows(tasks[status]), status
        seen += statuses
    assert sorted(seen) == sorted(tasks)


def task_sections(page: str) -> list[tuple[list[str], list]]:
    """Return each diagnostic task shown on a page: its status names, its level rows."""
    out = []
    for section in page.split('class="diagnostic-task">')[1:]:
        title = re.match(r'<strong>(.*?)</strong>', section, re.DOTALL)
        assert title, section[:200]
        out.append((plain(title.group(1)).split(', '),
                    table_rows(section, 'diagnostic-levels', 3)))
    return out


def level_rows(task: DiagnosticTask) -> list[tuple[str, str, str]]:
    """Return the rows a task's level table shows: level, message, when (as text)."""
    return [(row.level, row.message, row.when.replace('`', '')) for row in task.levels]


def plain(text: str) -> str:
    """Return a cell's HTML as text, Sphinx's smart quotes undone."""
    text = html.unescape(re.sub(r'<[^>]+>', '', text)).strip()
    for fancy, ascii_text in SMART_QUOTES.items():
        text = text.replace(fancy, ascii_text)
    return text


def table_cells(page: str, css_class: str, columns: int) -> list:
    """Return the body rows of the first table of css_class on an HTML page, as HTML."""
    table = page[page.index(css_class):]
    table = table[:table.index('</table>')]
    cells = re.findall(r'<td>(.*?)</td>', table, re.DOTALL)
    return [tuple(cells[i:i + columns]) for i in range(0, len(cells), columns)]


def table_rows(page: str, css_class: str, columns: int) -> list:
    """Return the body rows of the first table of css_class on an HTML page, as text."""
    return [tuple(plain(cell) for cell in row) for row in table_cells(page, css_class, columns)]


def test_no_page_mentions_issues():
    found = [f'{path}:{number}: {line.strip()}'
             for path, text in documentation().items()
             for number, line in enumerate(text.splitlines(), 1) if ISSUE.search(line)]
    assert not found, 'user-facing text mentions issues:\n' + '\n'.join(found)


def markdown_pages() -> dict:
    """Return {path: text} of the documentation's markdown sources and the README."""
    pages = {path: path.read_text() for path in sorted(DOC.rglob('*.md'))
             if '_build' not in path.parts and 'figures' not in path.parts}
    pages[REPO_ROOT / 'README.md'] = (REPO_ROOT / 'README.md').read_text()
    return pages


def test_no_line_of_a_paragraph_starts_a_block_quote_by_accident():
    # markdown: a paragraph's line that begins with '>' (say '> 0)' after a line break)
    # starts a block quote in the middle of the sentence
    found = []
    for path, text in markdown_pages().items():
        previous, fenced = '', False
        for number, line in enumerate(text.splitlines(), 1):
            if line.lstrip().startswith(('```', '~~~')):
                fenced = not fenced
            elif not fenced and line.startswith('>') and previous.strip() \
                    and not previous.startswith('>'):
                found.append(f'{path.relative_to(REPO_ROOT)}:{number}: {line}')
            previous = line
    assert not found, 'a line starts a block quote inside a paragraph:\n' + '\n'.join(found)


def toctree_entries(text: str) -> list:
    """Return the entries (document names) of every toctree of a page."""
    entries = []
    for block in re.findall(r'```\{toctree\}\n(.*?)```', text, re.DOTALL):
        entries += [line.strip() for line in block.splitlines()
                    if line.strip() and not line.startswith(':')]
    return entries


def test_no_draft_is_in_the_navigation():
    # a draft design note is an orphan page (built, linked, not in the navigation); every
    # other page of doc/design/ is in the navigation
    listed = set(toctree_entries((DOC / 'index.md').read_text()))
    assert not any('*' in entry for entry in listed), 'a glob would list the drafts'
    for path in sorted((DOC / 'design').glob('*.md')):
        text = path.read_text()
        draft = '(draft)' in next(line for line in text.splitlines() if line.startswith('# '))
        name = f'design/{path.stem}'
        if draft:
            assert name not in listed and text.startswith('---\norphan: true\n---\n'), name
        else:
            assert name in listed, f'{name} is in no toctree'
