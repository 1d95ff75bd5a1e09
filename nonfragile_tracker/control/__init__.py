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
"""
from __future__ import annotations

import ast
import importlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ['lazy_exports']


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
    tree = ast.parse(Path(str(module.__file__)).read_text(encoding='utf-8'))
    where: dict[str, tuple[str, str]] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == 'TYPE_CHECKING':
            for imp in node.body:
                if isinstance(imp, ast.ImportFrom) and imp.level == 1 and imp.module:
                    for alias in imp.names:
                        where[alias.asname or alias.name] = (imp.module, alias.name)

    def __getattr__(name: str) -> Any:
        if name not in where:
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        source, attr = where[name]
        value = getattr(importlib.import_module(f'{package}.{source}'), attr)
        setattr(module, name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(module)) | set(where))

    return __getattr__, __dir__
