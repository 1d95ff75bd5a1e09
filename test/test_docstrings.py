"""Docstrings: every public function and method of the checked modules documents each of its
parameters by name in a numpydoc ``Parameters`` section, and documents no parameter it does
not have (python-control's ``control/tests/docstrings_test.py`` checks its package the same
way; we keep neither its hashes nor its deprecation handling).

Public means: defined in the module (not imported into it), no leading underscore; methods
are those a public class defines itself (inherited ones are checked where they are defined),
static and class methods included, properties skipped.  A class's own ``__init__`` counts as
public: its parameters are documented in the ``__init__`` docstring or, numpydoc's usual
place, in the class docstring.  ``*args`` and ``**kwargs`` are documented as such.
Docstrings are parsed with numpydoc's own parser (``numpydoc.docscrape``, pinned in
requirements.txt, the docs build's version).

``CHECKED`` is every module of the package, found from its files (nothing to register).

Module docstrings are short: at most 15 lines (what the module is for and its doc page; the
reference material lives in doc/), every file of the package; each names its doc page
(``doc/<page>.md``, which exists).
"""
from __future__ import annotations

import ast
import importlib
import inspect
import re
import warnings
from collections.abc import Callable, Iterator

import pytest
from numpydoc.docscrape import ClassDoc, FunctionDoc, NumpyDocString

from conftest import ROOT

#: The modules whose public functions must document every parameter (dotted names): every
#: module of the package, found from its files (a new module is checked without registering it).
CHECKED = tuple(sorted(
    '.'.join(p.relative_to(ROOT).with_suffix('').parts)
    for p in (ROOT / 'nonfragile_tracker').rglob('*.py') if p.stem != '__init__'))


def _defined_in(obj: object, module: str) -> bool:
    return getattr(obj, '__module__', None) == module


def _own_source(func: Callable[..., object], module: object) -> bool:
    """Whether ``func`` was written in ``module``'s file (not generated, e.g. a dataclass's
    ``__init__``, whose parameters are its documented fields)."""
    code = getattr(inspect.unwrap(func), '__code__', None)
    return code is not None and code.co_filename == getattr(module, '__file__', None)


def public_callables(module_name: str) -> Iterator[tuple[str, Callable[..., object], str]]:
    """(qualified name, function, where its parameters are documented) of every public
    function and method of ``module_name``; the last is ``'function'`` or ``'init'``."""
    module = importlib.import_module(module_name)
    for name, obj in vars(module).items():
        if name.startswith('_') or not _defined_in(obj, module_name):
            continue
        if inspect.isfunction(obj):
            yield name, obj, 'function'
        elif inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if isinstance(member, (staticmethod, classmethod)):
                    member = member.__func__
                if not inspect.isfunction(member) or not _own_source(member, module):
                    continue
                if attr == '__init__':
                    yield f'{name}.__init__', member, 'init'
                elif not attr.startswith('_'):
                    yield f'{name}.{attr}', member, 'function'


def parameter_names(func: Callable[..., object]) -> list[str]:
    """The parameters a docstring must name: ``self``/``cls`` left out, ``*args`` and
    ``**kwargs`` with their stars."""
    names = []
    params = list(inspect.signature(func).parameters.values())
    if params and params[0].name in ('self', 'cls'):
        params = params[1:]
    for p in params:
        stars = {inspect.Parameter.VAR_POSITIONAL: '*',
                 inspect.Parameter.VAR_KEYWORD: '**'}.get(p.kind, '')
        names.append(stars + p.name)
    return names


def _section_names(doc: NumpyDocString) -> list[str]:
    names = []
    for entry in doc['Parameters']:
        names += [n.strip() for n in entry.name.split(',') if n.strip()]
    return names


def documented_names(func: Callable[..., object], kind: str,
                     owner: type | None = None) -> list[str] | None:
    """The names of ``func``'s numpydoc ``Parameters`` section (``None``: no section); for
    ``__init__`` its own docstring's, else its class's.  numpydoc's warnings (an unknown
    or malformed section) are the caller's to catch."""
    if kind == 'init':
        own = NumpyDocString(inspect.getdoc(func) or '')
        if own['Parameters']:
            return _section_names(own)
        assert owner is not None
        doc: NumpyDocString = ClassDoc(owner, config={'show_class_members': False})
    else:
        doc = FunctionDoc(func)
    return _section_names(doc) if doc['Parameters'] else None


def problems(module_name: str) -> list[str]:
    """One line per function whose Parameters section is missing, incomplete or stale, or
    whose docstring numpydoc warns about."""
    module = importlib.import_module(module_name)
    found = []
    for qualname, func, kind in public_callables(module_name):
        wanted = parameter_names(func)
        owner = getattr(module, qualname.split('.')[0]) if kind == 'init' else None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            documented = documented_names(func, kind, owner)
        line = inspect.getsourcelines(func)[1]
        where = f'{module_name}:{line} {qualname}'
        found += [f'{where}: numpydoc: {w.message}' for w in caught]
        if documented is None:
            if wanted:
                found.append(f'{where}: no Parameters section (takes {", ".join(wanted)})')
            continue
        missing = [n for n in wanted if n not in documented]
        stale = [n for n in documented if n not in wanted]
        if missing:
            found.append(f'{where}: not documented: {", ".join(missing)}')
        if stale:
            found.append(f'{where}: documented but not a parameter: {", ".join(stale)}')
    return found


@pytest.mark.parametrize('module_name', CHECKED)
def test_public_functions_document_their_parameters(module_name):
    found = problems(module_name)
    assert not found, '\n'.join(found)


def test_every_module_of_the_package_is_checked():
    # derived from the files: the check finds the core and the shell, and enough callables
    # that a broken walk (an empty list, a wrong root) cannot pass unseen
    assert {'nonfragile_tracker.control.simulation.tracker',
            'nonfragile_tracker.control.simulation.interfaces',
            'nonfragile_tracker.nodes.tracker', 'nonfragile_tracker.cli'} <= set(CHECKED)
    assert len(CHECKED) > 90, len(CHECKED)
    counted = sum(len(list(public_callables(name))) for name in CHECKED)
    assert counted > 120, counted


#: Module docstrings say what the module is for and name its doc page; reference material
#: (input rules, message layouts, algorithms, file formats) lives once, in doc/.
MAX_MODULE_DOCSTRING_LINES = 15

#: Every file of the package, package ``__init__``s included (found from the files).
MODULE_FILES = tuple(sorted(p.relative_to(ROOT).as_posix()
                            for p in (ROOT / 'nonfragile_tracker').rglob('*.py')))


def module_docstring_lines(path: str) -> int:
    """The number of lines of the module docstring of ``path`` (relative to the root)."""
    doc = ast.get_docstring(ast.parse((ROOT / path).read_text()))
    return len(doc.splitlines()) if doc else 0


@pytest.mark.parametrize('path', MODULE_FILES)
def test_module_docstrings_are_short(path):
    lines = module_docstring_lines(path)
    assert lines <= MAX_MODULE_DOCSTRING_LINES, (
        f'{path}: module docstring of {lines} lines; say what the module is for in about 10 '
        f'and move the reference material into its doc/ page (doc/developing.md, '
        f'"Documentation")')


@pytest.mark.parametrize('path', MODULE_FILES)
def test_module_docstrings_name_their_doc_page(path):
    doc = ast.get_docstring(ast.parse((ROOT / path).read_text())) or ''
    pages = re.findall(r'doc/[\w/-]+\.md', doc)
    assert pages, f'{path}: the module docstring names no doc page (e.g. "See doc/theory.md")'
    missing = [page for page in pages if not (ROOT / page).is_file()]
    assert not missing, f'{path}: names doc pages that do not exist: {missing}'


def test_the_short_docstring_check_sees_the_package():
    # derived from the files, so a broken walk cannot pass unseen
    assert len(MODULE_FILES) > 90 and 'nonfragile_tracker/__init__.py' in MODULE_FILES
