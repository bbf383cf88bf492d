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
Sphinx configuration of the tskf_ros documentation (MyST Markdown, the furo theme).

Build: `./run docs` (python -m sphinx -W -n --keep-going -b html doc doc/_build/html).
rosdoc2 (`rosdoc2 build --package-path .`) finds this `doc/` folder by itself, copies it
into its own Sphinx project (beside a copy of the README) and executes this file from that
project's conf.py, in that project's folder: the paths below work from both folders.
"""

import os
from pathlib import Path
import sys

# This folder: where Sphinx executes this file (sphinx-build), or doc/ below it (rosdoc2's
# project, whose folder holds the copies of doc/ and of the README).
HERE = Path('doc') if (Path('doc') / '_ext').is_dir() and not Path('_ext').is_dir() else Path()
# doc/_ext: the directives of the generated tables (parameters from config/schema/*.yaml,
# topics, services, diagnostics and overviews from tskf_ros.messages)
sys.path.insert(0, os.path.abspath(HERE / '_ext'))
if HERE != Path() and not Path('docs').exists():
    # rosdoc2's copy of the README shows the figures as docs/NAME.png, as in the repository
    # (figures/ is a copy of docs/ there)
    Path('docs').symlink_to(HERE / 'figures', target_is_directory=True)

project = 'tskf_ros'
author = 'tskf_ros maintainers'
copyright = 'tskf_ros maintainers, Apache-2.0'   # noqa: A001 - the name Sphinx reads
release = '0.1.0'

extensions = ['myst_parser', 'parameter_tables', 'interface_tables', 'overview_tables']
root_doc = 'index'
exclude_patterns = [str(HERE / '_build'), str(HERE / '_ext'), 'Thumbs.db', '.DS_Store']
if HERE != Path():
    # rosdoc2's project: not the pages of the docs/ link, nor the index.rst it writes into a
    # folder of doc/ that has an index.md already (the nodes' overview)
    exclude_patterns += ['docs'] + [str(index) for index in HERE.rglob('index.rst')
                                    if index.with_suffix('.md').is_file()]
# `figures` is a link to ../docs (the figures the README shows too); its markdown notes
# are pages of their own, listed in the toctrees
myst_enable_extensions = ['colon_fence', 'deflist', 'dollarmath']
# [text](#a-heading) links to headings down to ###, as on GitHub
myst_heading_anchors = 3
# a design draft that skips a heading level is still a good draft
suppress_warnings = ['myst.header']

html_theme = 'furo'
html_title = 'tskf_ros'

# rosdoc2: keep this theme when furo is installed (its default replaces it), and keep the
# extensions above (its default removes those it does not know: every generated table)
rosdoc2_settings = {'override_theme': False, 'allow_other_extensions': True}
