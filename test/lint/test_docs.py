"""The documentation builds (Sphinx, warnings as errors, nitpicky) and says nothing of issues."""

from pathlib import Path
import re
import subprocess
import sys

from documented_commands import documentation

REPO_ROOT = Path(__file__).resolve().parents[2]
DOC = REPO_ROOT / 'doc'
# the project rule: no user-facing text mentions issues (of a tracker or otherwise)
ISSUE = re.compile(r'\bissues?\b', re.IGNORECASE)


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


def test_no_page_mentions_issues():
    found = [f'{path}:{number}: {line.strip()}'
             for path, text in documentation().items()
             for number, line in enumerate(text.splitlines(), 1) if ISSUE.search(line)]
    assert not found, 'user-facing text mentions issues:\n' + '\n'.join(found)
