"""Sphinx configuration of the package documentation (rosdoc2 uses ``doc/`` as it is).

Build: ``make docs`` or ``sphinx-build -W --keep-going -b html doc <out>`` (the test
``test/package/test_docs.py`` does the same with warnings as errors).
"""
from __future__ import annotations

import sys
from pathlib import Path

project = 'nonfragile_tracker'
author = 'nonfragile_tracker maintainers'
copyright = '2026, nonfragile_tracker maintainers'
release = version = '0.1.0'

extensions = [
    'myst_parser',
    'sphinx.ext.autodoc',
    'sphinx.ext.napoleon',
    'sphinx.ext.mathjax',
]
source_suffix = {'.md': 'markdown', '.rst': 'restructuredtext'}
root_doc = 'index'
# rosdoc2 runs sphinx-apidoc for ament_python packages, writing modules.rst and one stub per
# module into this directory; api/ documents every module already, so the stubs are ignored
exclude_patterns = ['_build', 'modules.rst', 'nonfragile_tracker.rst', 'nonfragile_tracker.*.rst']
myst_enable_extensions = ['dollarmath', 'amsmath', 'deflist', 'colon_fence']
myst_heading_anchors = 4

# every reference must resolve: a broken one is a warning, and the suite builds with -W
nitpicky = True
suppress_warnings: list[str] = []
# third-party objects: numpy, scipy, the standard library, rclpy, rosbags and Dask are not
# in this build (no intersphinx inventories offline), so references to them cannot resolve;
# ``ndarray`` is numpydoc's short name for numpy.ndarray in Attributes types;
# ``DataclassInstance`` is typeshed's protocol (``_typeshed``, no runtime object), the bound
# of a settings TypeVar
nitpick_ignore = [('py:class', 'ndarray'), ('py:class', 'DataclassInstance')]
nitpick_ignore_regex = [
    (r'py:.*', r'(numpy|scipy|pathlib|collections\.abc|argparse|concurrent\.futures|rclpy'
               r'|rosbags|distributed)\..*'),
]

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


def _no_inline_attribute_type(app, what, name, obj, options, lines):
    """Keep napoleon from reading an attribute's first line as ``type: description``.

    Our attribute, data and property docstrings begin with prose (``#: Receive-time window
    (s): a reference ...``), never with a type; napoleon would render the text before the
    first colon as a type (a cross-reference to a class that does not exist) and drop it
    from the description.  An empty comment (``..``) as the first line leaves napoleon no
    inline type to find and renders as nothing.
    """
    if what in ('attribute', 'data', 'property') and lines and lines[0].strip():
        lines[:0] = ['..', '']


def setup(app):
    """Put the package of this source tree and doc/_ext on the path, load the extension.

    Done here, from ``app.srcdir``, not from ``__file__``: rosdoc2 runs this file through
    ``exec`` from a wrapping conf.py elsewhere, where ``__file__`` names the wrapper.
    """
    src = Path(app.srcdir).resolve()
    for path in (str(src / '_ext'), str(src.parent)):
        if path not in sys.path:
            sys.path.insert(0, path)
    app.setup_extension('nonfragile_docs')
    # before napoleon's own handler (priority 500)
    app.connect('autodoc-process-docstring', _no_inline_attribute_type, priority=400)
