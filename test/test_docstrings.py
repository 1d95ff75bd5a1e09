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

``CHECKED`` lists the modules checked, by part: every module of the package
(``test_every_module_of_the_package_is_checked`` fails when a new one is not added).
"""
from __future__ import annotations

import importlib
import inspect
import warnings
from collections.abc import Callable, Iterator

import pytest
from numpydoc.docscrape import ClassDoc, FunctionDoc, NumpyDocString

from conftest import ROOT

#: The modules whose public functions must document every parameter (dotted names).
CHECKED = tuple(
    ['nonfragile_tracker.control.validate']
    + [f'nonfragile_tracker.control.{part}.errors'
       for part in ('synthesis', 'simulation', 'identification')]
    + [f'nonfragile_tracker.control.synthesis.{m}' for m in (
        'delay', 'analysis', 'design', 'problem', 'sdp', 'certificate', 'search', 'lmi',
        'delay_dependent', 'input_delay', 'input_delay_certificate',
        'latency_design', 'saturation', 'sweep',
        'worst_delta')]
    + [f'nonfragile_tracker.control.simulation.{m}' for m in (
        'model', 'reference', 'metrics', 'sensors', 'actuator', 'simulate', 'batch', 'batch_parts',
        'batch_ideal', 'law', 'study', 'follow', 'limits', 'trajectory', 'loop', 'predictor', 'gains',
        'timing')]
    + [f'nonfragile_tracker.control.identification.{m}' for m in (
        'identify', 'lag_fit', 'records', 'monitor', 'excitation')]
    + [f'nonfragile_tracker.{m}' for m in (
        'files', 'resources', 'scenario', 'golden', 'reproduce', 'runner', 'replayer',
        'errors', 'topics', 'msgconv', 'parallel', 'cli', 'tracker_inputs', 'robot',
        'region_check', 'bringup')]
    + [f'nonfragile_tracker.bag.{m}' for m in (
        'compare', 'reader', 'writer', 'repair', 'errors', 'typestore', 'report', 'replay',
        'motion')]
    + [f'nonfragile_tracker.commands.{m}' for m in (
        'argtypes', 'common', 'synthesis', 'identify', 'latency_design', 'sweep', 'run',
        'study', 'trajectory', 'bag', 'reproduce', 'golden', 'bringup')]
    + [f'nonfragile_tracker.nodes.{m}' for m in (
        'trajectory_io', 'entry', 'errors', 'common', 'plant', 'reference', 'tracker',
        'recorder', 'workarounds', 'bringup')])


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
    modules = {'.'.join(p.relative_to(ROOT).with_suffix('').parts)
               for p in (ROOT / 'nonfragile_tracker').rglob('*.py') if p.stem != '__init__'}
    assert len(set(CHECKED)) == len(CHECKED)
    assert set(CHECKED) == modules, (sorted(modules - set(CHECKED)),
                                     sorted(set(CHECKED) - modules))
    counted = sum(len(list(public_callables(name))) for name in CHECKED)
    assert counted > 120, counted


# --- the checker checks: planted docstrings --------------------------------------------

def _complete(a, b=1, *rest, key=None, **options):
    """Complete.

    Parameters
    ----------
    a, b : int
        Two.
    *rest : int
        More.
    key : str, optional
        A key.
    **options
        Extra.
    """


def _partial(a, b):
    """Partial: ``b`` missing, ``c`` stale.

    Parameters
    ----------
    a : int
        One.
    c : int
        Not a parameter.
    """


def _undocumented(a):
    """No section."""


def _misspelt(a):
    """A misspelt section header.

    Paramters
    ---------
    a : int
        One.
    """


class _Documented:
    """A class whose ``__init__`` is documented here.

    Parameters
    ----------
    x : float
        Speed [m/s].
    """

    def __init__(self, x):
        self.x = x

    @classmethod
    def make(cls, y):
        """Make one.

        Parameters
        ----------
        y : float
            Speed [m/s].
        """
        return cls(y)


def test_checker_reads_numpydoc_sections():
    assert parameter_names(_complete) == ['a', 'b', '*rest', 'key', '**options']
    assert documented_names(_complete, 'function') == ['a', 'b', '*rest', 'key',
                                                       '**options']
    assert documented_names(_partial, 'function') == ['a', 'c']
    assert documented_names(_undocumented, 'function') is None
    assert documented_names(_Documented.__init__, 'init', _Documented) == ['x']
    assert parameter_names(_Documented.make) == ['y']
    assert parameter_names(_Documented.__init__) == ['x']


def test_checker_lists_missing_and_stale_names(monkeypatch):
    import types
    mod = types.ModuleType('planted')
    mod.__file__ = __file__
    for obj in (_complete, _partial, _undocumented, _misspelt, _Documented):
        public = obj.__name__.lstrip('_')
        monkeypatch.setattr(obj, '__module__', 'planted')
        setattr(mod, public, obj)
    monkeypatch.setitem(__import__('sys').modules, 'planted', mod)
    found = problems('planted')
    text = '\n'.join(found)
    assert len(found) == 5, text
    assert 'partial: not documented: b' in text
    assert 'partial: documented but not a parameter: c' in text
    assert 'undocumented: no Parameters section (takes a)' in text
    assert 'misspelt: numpydoc: Unknown section Paramters' in text
    assert 'misspelt: no Parameters section (takes a)' in text
