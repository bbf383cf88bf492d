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
Copyright and licence: ament_copyright as `ros2 pkg create` has it, and a check run everywhere.

ament_copyright is not among the wheels, so its test runs where it is installed (a ROS
workspace, the buildfarm); the header check of copyright_header.py and the licence text
check run everywhere.
"""

import hashlib
import importlib.util
from pathlib import Path

from copyright_header import header, header_problem, source_files, with_header
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
# sha256 of the Apache License 2.0 as the Apache Software Foundation publishes it
# (LICENSE-2.0.txt; the licence file of ament_copyright's apache2 template is the same text)
APACHE_2_SHA256 = 'cfc7749b96f63bd31c3c42b5c471bf756814053e847c10f3eb003417bc523d30'


@pytest.mark.skipif(importlib.util.find_spec('ament_copyright') is None,
                    reason='ament_copyright is not installed (no wheel: it comes with a ROS '
                    'workspace); the header check below runs instead')
@pytest.mark.copyright
@pytest.mark.linter
def test_copyright(lint_paths):
    from ament_copyright.main import main

    rc = main(argv=[*lint_paths, str(REPO_ROOT / 'LICENSE')])
    assert rc == 0, 'Found errors'


@pytest.mark.copyright
def test_every_source_file_starts_with_the_header():
    files = list(source_files())
    assert any(path.name == 'run' for path in files)           # the scripts are included
    problems = [f'{path.relative_to(REPO_ROOT)}: {problem}' for path in files
                if (problem := header_problem(path.read_text(encoding='utf-8')))]
    assert not problems, ('%d of %d source files lack the header (add it with '
                          '`python test/copyright_header.py --add`):\n%s'
                          % (len(problems), len(files), '\n'.join(problems)))


def test_the_licence_is_the_full_apache_2_text():
    text = (REPO_ROOT / 'LICENSE').read_text()
    assert 'TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION' in text
    assert hashlib.sha256(text.encode()).hexdigest() == APACHE_2_SHA256


def test_the_header_check_reads_shebangs_and_refuses_the_spdx_line_alone():
    body = '"""A module."""\nx = 1\n'
    assert header_problem(with_header(body)) is None
    assert with_header(body).startswith('\n'.join(header()) + '\n\n"""A module')
    script = '#!/usr/bin/env bash\nset -e\n'
    assert with_header(script).startswith('#!/usr/bin/env bash\n# Copyright 2026 ')
    assert header_problem(with_header(script)) is None
    assert with_header(with_header(body)) == with_header(body)
    assert header_problem('') is None
    assert 'first line' in header_problem(body)
    spdx_only = '\n'.join(header()[:2]) + '\n' + body
    assert 'Apache-2.0 notice' in header_problem(spdx_only)


@pytest.mark.skipif(importlib.util.find_spec('ament_copyright') is None,
                    reason='ament_copyright is not installed (no wheel)')
def test_ament_copyright_accepts_the_header_and_not_the_spdx_line_alone(tmp_path):
    from ament_copyright.main import main

    body = '"""A module."""\nx = 1\n'
    (tmp_path / 'good.py').write_text(with_header(body))
    (tmp_path / 'script.py').write_text(with_header('#!/usr/bin/env python3\n' + body))
    assert main(argv=[str(tmp_path)]) == 0
    (tmp_path / 'spdx_only.py').write_text('\n'.join(header()[:2]) + '\n' + body)
    assert main(argv=[str(tmp_path)]) == 1
