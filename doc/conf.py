"""Sphinx configuration of the package documentation (rosdoc2 uses ``doc/`` as it is).

Build: ``make docs`` or ``sphinx-build -W --keep-going -b html doc <out>`` (the test
``test/package/test_docs.py`` does the same with warnings as errors).
"""
from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
# the package from this source tree (not an installed copy) and the local extensions
sys.path[:0] = [str(HERE.parent), str(HERE / '_ext')]

project = 'nonfragile_tracker'
author = 'nonfragile_tracker maintainers'
copyright = '2026, nonfragile_tracker maintainers'
release = version = '0.1.0'

extensions = [
    'myst_parser',
    'sphinx.ext.autodoc',
    'sphinx.ext.napoleon',
    'sphinx.ext.mathjax',
    'nonfragile_docs',
]
source_suffix = {'.md': 'markdown', '.rst': 'restructuredtext'}
root_doc = 'index'
exclude_patterns = ['_build']
myst_enable_extensions = ['dollarmath', 'amsmath', 'deflist', 'colon_fence']
myst_heading_anchors = 3

# every reference must resolve: a broken one is a warning, and the suite builds with -W
nitpicky = False
suppress_warnings: list[str] = []

# members defined in each module (re-exports are documented where they are defined)
autodoc_default_options = {'members': True, 'show-inheritance': True,
                           'ignore-module-all': True}
autodoc_member_order = 'bysource'
autodoc_typehints = 'none'
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
# parameter types as text, not cross-references: 'shape (n, n)' names no object
napoleon_use_param = False

html_theme = 'sphinx_rtd_theme'
html_title = 'nonfragile_tracker'
html_static_path: list[str] = []
