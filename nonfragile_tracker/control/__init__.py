"""The ROS-free control core, in three parts.

:mod:`~nonfragile_tracker.control.synthesis`
    Gains and their certificates (numpy/scipy/cvxpy).
:mod:`~nonfragile_tracker.control.simulation`
    The step functions the nodes run and the in-process loops over them (no cvxpy).
:mod:`~nonfragile_tracker.control.identification`
    Latency and lags from commands and odometry; the runtime certificate monitor.

:mod:`~nonfragile_tracker.control.validate`, the one shape/number validator, is shared by
the three.  Arrows: synthesis -> identification -> simulation; none between synthesis and
simulation.  Nothing here imports rclpy, rosbags or the package's ROS layers.

Each part re-exports its public names (``from nonfragile_tracker.control.simulation import
Tracker``); a name's module is imported when the name is first used
(:func:`lazy_exports`), so importing a part costs nothing and the simulation never loads
cvxpy.

The modules were in one flat folder before (``nonfragile_tracker.control.lmi``, ...); those
paths still import, as the same module object, with a ``DeprecationWarning`` naming the new
path (:data:`MOVED`, :class:`MovedModules`).
"""
from __future__ import annotations

import importlib
import importlib.machinery
import sys
import warnings
from collections.abc import Callable, Mapping, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from importlib.abc import Loader

__all__ = ['lazy_exports', 'MOVED', 'MovedModules']

#: The flat layout's module names -> the part each moved to (the moves of one release; a
#: module added since has no old path).
MOVED = {
    **dict.fromkeys(('problem', 'sdp', 'search', 'lmi', 'design', 'delay_dependent',
                     'input_delay', 'latency_design', 'analysis', 'delay', 'saturation',
                     'sweep'), 'synthesis'),
    **dict.fromkeys(('model', 'actuator', 'sensors', 'predictor', 'reference', 'trajectory',
                     'limits', 'follow', 'loop', 'simulate', 'batch', 'study', 'metrics',
                     'gains'), 'simulation'),
    **dict.fromkeys(('identify', 'recording', 'monitor'), 'identification'),
}


def lazy_exports(package: str) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` of a package that re-exports its modules' names lazily.

    The names are those the package's ``__init__.py`` imports from its own modules under
    ``if TYPE_CHECKING:``: type checkers and readers see plain imports, ``__all__`` lists
    the same names (ruff checks that the two agree), and at run time a name's module is
    imported on first use (PEP 562), then the name is cached in the package.

    Parameters
    ----------
    package : str
        The package's ``__name__`` (already in ``sys.modules``: call this from its
        ``__init__``).

    Returns
    -------
    tuple of callable
        ``(__getattr__, __dir__)`` for the package's module namespace.
    """
    module = sys.modules[package]
    cache: list[dict[str, tuple[str, str]]] = []

    def where() -> dict[str, tuple[str, str]]:
        # read on first use (importing the package parses nothing); built whole, then
        # published, so a thread never sees half a table
        if not cache:
            import ast
            with open(str(module.__file__), encoding='utf-8') as source:
                tree = ast.parse(source.read())
            table = {alias.asname or alias.name: (imp.module, alias.name)
                     for node in tree.body
                     if isinstance(node, ast.If) and ast.unparse(node.test) == 'TYPE_CHECKING'
                     for imp in node.body
                     if isinstance(imp, ast.ImportFrom) and imp.level == 1 and imp.module
                     for alias in imp.names}
            cache.append(table)
        return cache[0]

    def __getattr__(name: str) -> Any:
        if name.startswith('__') or name not in where():
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        source, attr = where()[name]
        value = getattr(importlib.import_module(f'{package}.{source}'), attr)
        setattr(module, name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(module)) | set(where()))

    return __getattr__, __dir__


def _bootstrap(filename: str) -> bool:
    """Whether ``warnings`` skips a frame of this file when counting ``stacklevel``."""
    return 'importlib' in filename and '_bootstrap' in filename


def _import_machinery(filename: str) -> bool:
    return filename in (__file__, importlib.__file__) or _bootstrap(filename)


class MovedModules:
    """Imports a module's old path as the module itself, with a ``DeprecationWarning``.

    A meta path finder and loader (PEP 451; duck-typed: ``importlib.abc`` costs 25 ms of
    imports in Python 3.11) for ``PACKAGE.OLD``: its loader imports the new module and
    returns that very object, so both names give one module (no second import: classes,
    ``isinstance`` and module state are shared) and ``sys.modules`` holds it under both.
    Any other name is left to the other finders (an unknown one stays a
    ``ModuleNotFoundError``).

    Parameters
    ----------
    package : str
        The package whose old module paths are kept (``nonfragile_tracker.control``).
    moved : mapping of str to str
        Old module name -> the subpackage it moved to (:data:`MOVED`).
    """

    def __init__(self, package: str, moved: Mapping[str, str]) -> None:
        self.package = package
        self.new = {f'{package}.{old}': f'{package}.{part}.{old}' for old, part in moved.items()}
        self._specs: dict[str, Any] = {}

    def find_spec(self, fullname: str, path: Sequence[str] | None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        """A spec for an old path, None for any other name.

        Parameters
        ----------
        fullname : str
            The module asked for.
        path : sequence of str or None
            The parent package's ``__path__`` (unused).
        target : module, optional
            Unused (reloads).

        Returns
        -------
        ModuleSpec or None
        """
        if fullname not in self.new:
            return None
        return importlib.machinery.ModuleSpec(fullname, cast('Loader', self))

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        """The new module (imported if need be); warns, pointing at the importing line.

        Parameters
        ----------
        spec : ModuleSpec
            The old path's spec (from :meth:`find_spec`).

        Returns
        -------
        module
        """
        new = self.new[spec.name]
        # the first frame outside the import system: the user's import (warnings does not
        # count the frames of importlib._bootstrap)
        level, frame = 1, sys._getframe(0)
        while frame.f_back is not None and _import_machinery(frame.f_code.co_filename):
            frame = frame.f_back
            level += not _bootstrap(frame.f_code.co_filename)
        warnings.warn(f'{spec.name} is deprecated: the module moved to {new}; import it from '
                      f'there (or its public names from {new.rpartition(".")[0]})',
                      DeprecationWarning, stacklevel=level)
        module = importlib.import_module(new)
        self._specs[new] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run (the module is loaded); give it back its own spec.

        Parameters
        ----------
        module : module
            The new module, whose ``__spec__`` the import system set to the old path's.
        """
        module.__spec__ = self._specs[module.__name__]


if not any(getattr(finder, 'package', None) == __name__ for finder in sys.meta_path):
    sys.meta_path.append(MovedModules(__name__, MOVED))
