"""
Sphinx configuration of the tskf_ros documentation (MyST Markdown, the furo theme).

Build: `./run docs` (python -m sphinx -W -n --keep-going -b html doc doc/_build/html).
rosdoc2 finds this `doc/` folder by itself, copies it and executes this file from its own
conf.py; the one path here (`_ext`) is relative to the folder Sphinx executes it in.
"""

import os
import sys

# doc/_ext: the parameter-table directive (node pages from config/schema/*.yaml).  Sphinx
# runs this file in its own folder, under sphinx-build and under rosdoc2 alike.
sys.path.insert(0, os.path.abspath('_ext'))

project = 'tskf_ros'
author = 'tskf_ros maintainers'
copyright = 'tskf_ros maintainers, Apache-2.0'   # noqa: A001 - the name Sphinx reads
release = '0.1.0'

extensions = ['myst_parser', 'parameter_tables', 'interface_tables', 'overview_tables']
root_doc = 'index'
exclude_patterns = ['_build', '_ext', 'Thumbs.db', '.DS_Store']
# `figures` is a link to ../docs (the figures the README shows too); its markdown notes
# are pages of their own, listed in the toctrees
myst_enable_extensions = ['colon_fence', 'deflist', 'dollarmath']
# [text](#a-heading) links to headings down to ###, as on GitHub
myst_heading_anchors = 3
# a design draft that skips a heading level is still a good draft
suppress_warnings = ['myst.header']

html_theme = 'furo'
html_title = 'tskf_ros'

# rosdoc2: keep this theme when furo is installed (its default replaces it)
rosdoc2_settings = {'override_theme': False}
