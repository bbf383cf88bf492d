"""The docs build (-W -n), show every node's parameters and interface, and mention no issues."""

import html
from pathlib import Path
import re
import subprocess
import sys

from documented_commands import documentation

from tskf_ros.messages.node_interfaces import INTERFACES
from tskf_ros.messages.parameter_schema import load_schema

REPO_ROOT = Path(__file__).resolve().parents[2]
DOC = REPO_ROOT / 'doc'
# the project rule: no user-facing text mentions issues (of a tracker or otherwise)
ISSUE = re.compile(r'\bissues?\b', re.IGNORECASE)
SMART_QUOTES = {'\u2018': "'", '\u2019': "'", '\u201c': '"', '\u201d': '"',
                '\u2014': '---', '\u2013': '--', '\u2026': '...'}


def test_the_documentation_builds_without_a_warning(tmp_path):
    # as ./run docs, into a temporary directory: -W warnings are errors, -n every
    # cross-reference must resolve, --keep-going reports all of them at once
    out = tmp_path / 'html'
    build = subprocess.run(
        [sys.executable, '-m', 'sphinx', '-W', '-n', '--keep-going', '-q', '-b', 'html',
         '-d', str(tmp_path / 'doctrees'), str(DOC), str(out)],
        capture_output=True, text=True, timeout=600, check=False)
    assert build.returncode == 0, \
        f'sphinx-build failed (exit {build.returncode}):\n{build.stderr}{build.stdout}'
    assert (out / 'index.html').is_file()
    # every design draft is a page (the glob toctree picks up new ones)
    drafts = sorted(path.stem for path in (DOC / 'design').glob('*.md'))
    assert drafts, 'doc/design/ holds no draft'
    missing = [name for name in drafts if not (out / 'design' / f'{name}.html').is_file()]
    assert not missing, f'design drafts without a page: {missing}'
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
        shown = [plain(status) for status in
                 re.findall(r'class="diagnostic-task"><strong>(.*?)</strong>', page, re.DOTALL)]
        assert shown == declared.status_names(), name


def plain(text: str) -> str:
    """Return a cell's HTML as text, Sphinx's smart quotes undone."""
    text = html.unescape(re.sub(r'<[^>]+>', '', text)).strip()
    for fancy, ascii_text in SMART_QUOTES.items():
        text = text.replace(fancy, ascii_text)
    return text


def table_rows(page: str, css_class: str, columns: int) -> list:
    """Return the body rows of the first table of css_class on an HTML page, as text."""
    table = page[page.index(css_class):]
    table = table[:table.index('</table>')]
    cells = [plain(cell) for cell in re.findall(r'<td>(.*?)</td>', table, re.DOTALL)]
    return [tuple(cells[i:i + columns]) for i in range(0, len(cells), columns)]


def test_no_page_mentions_issues():
    found = [f'{path}:{number}: {line.strip()}'
             for path, text in documentation().items()
             for number, line in enumerate(text.splitlines(), 1) if ISSUE.search(line)]
    assert not found, 'user-facing text mentions issues:\n' + '\n'.join(found)
