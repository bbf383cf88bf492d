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
The copyright and licence header of every source file: the check, and the command adding it.

The header is the copyright line, the SPDX identifier, then Apache's own notice (the form
ament_copyright recognises as Apache-2.0: it finds no licence in the SPDX line alone); it
comes first in the file, after a shebang line if any.  Source files: every *.py file and
every script (a file with no suffix that starts with #!) of the repository, outside the
hidden, virtual-environment and generated folders.

    python test/copyright_header.py          # name the files without the header
    python test/copyright_header.py --add    # add it to each of them (2026 as the year)
"""

import argparse
import os
from pathlib import Path
import re
import sys
from typing import Iterator, List, Optional

REPO_ROOT = Path(__file__).resolve().parent.parent
COPYRIGHT = re.compile(r'# Copyright \d{4}(-\d{4})? The tskf_ros authors')
NOTICE = [
    '# SPDX-License-Identifier: Apache-2.0',
    '#',
    '# Licensed under the Apache License, Version 2.0 (the "License");',
    '# you may not use this file except in compliance with the License.',
    '# You may obtain a copy of the License at',
    '#',
    '#     http://www.apache.org/licenses/LICENSE-2.0',
    '#',
    '# Unless required by applicable law or agreed to in writing, software',
    '# distributed under the License is distributed on an "AS IS" BASIS,',
    '# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.',
    '# See the License for the specific language governing permissions and',
    '# limitations under the License.',
]
# folders never searched: generated trees, caches and the built documentation (hidden
# folders are skipped too, except .ci)
SKIPPED = {'build', 'install', 'log', 'results', '__pycache__', '_build'}


def header(year: int = 2026) -> List[str]:
    """Return the header's lines."""
    return [f'# Copyright {year} The tskf_ros authors', *NOTICE]


def source_files(root: Path = REPO_ROOT) -> Iterator[Path]:
    """Yield the repository's source files (see the module), sorted within each folder."""
    for folder, subfolders, names in os.walk(root):
        subfolders[:] = sorted(
            name for name in subfolders
            if (name == '.ci' or not name.startswith('.')) and name not in SKIPPED
            and not name.endswith('.egg-info'))
        for name in sorted(names):
            path = Path(folder) / name
            if name.endswith('.py') or (not path.suffix and is_script(path)):
                yield path


def is_script(path: Path) -> bool:
    """Return whether a file starts with a shebang (#!)."""
    with open(path, 'rb') as f:
        return f.read(2) == b'#!'


def header_problem(text: str) -> Optional[str]:
    """Return what is wrong with a source text's header, or None (an empty file has none)."""
    lines = text.splitlines()
    if lines and lines[0].startswith('#!'):
        lines = lines[1:]
    if not ''.join(lines).strip():
        return None
    if not COPYRIGHT.fullmatch(lines[0]):
        return f'the first line is not "# Copyright YEAR The tskf_ros authors": {lines[0]!r}'
    got = lines[1:1 + len(NOTICE)]
    for want, line in zip(NOTICE, got + [''] * len(NOTICE)):
        if line != want:
            return f'the header differs from the Apache-2.0 notice at {line!r} (want {want!r})'
    return None


def with_header(text: str, year: int = 2026) -> str:
    """Return text with the header in front (after a shebang line), unless it has one."""
    if header_problem(text) is None:
        return text
    shebang, rest = '', text
    if text.startswith('#!'):
        shebang, _, rest = text.partition('\n')
        shebang += '\n'
    return shebang + '\n'.join(header(year)) + '\n\n' + rest.lstrip('\n')


def main(argv: Optional[List[str]] = None) -> int:
    """List the source files without the header, or add it to them (--add)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0].strip())
    parser.add_argument('--add', action='store_true', help='add the header where it is missing')
    args = parser.parse_args(argv)
    missing = [path for path in source_files()
               if header_problem(path.read_text(encoding='utf-8')) is not None]
    for path in missing:
        if args.add:
            path.write_text(with_header(path.read_text(encoding='utf-8')), encoding='utf-8')
        print(f'{"added the header to" if args.add else "no header:"} '
              f'{path.relative_to(REPO_ROOT)}')
    return 0 if args.add or not missing else 1


if __name__ == '__main__':
    sys.exit(main())
