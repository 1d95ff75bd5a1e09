"""argparse ``type=`` functions for numbers: a bad value is a usage error (exit 2).

Each raises :class:`argparse.ArgumentTypeError`, so argparse prints the usage line
and ``error: argument --x: ...`` naming the option and the value.

See doc/cli.md, section "Exit codes and errors".
"""
from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TypeVar

__all__ = ['finite_float', 'positive_float', 'nonnegative_float', 'positive_int',
           'nonnegative_int', 'add_executor_arguments']


def finite_float(text: str) -> float:
    """A finite real number (no ``nan``/``inf``).

    Parameters
    ----------
    text : str
        The option's value as typed.
    """
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f'expected a finite number, got {text!r}')
    return x


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None


_X = TypeVar('_X', int, float)


def _at_least(parse: Callable[[str], _X], low: _X, strict: bool, kind: str, name: str,
              summary: str) -> Callable[[str], _X]:
    """The ``type=`` function ``name``: ``parse``, then check the lower bound.

    A value must be above ``low`` (``strict``) or at least ``low``; else the usage error
    names ``kind`` and the bound.  One rule for every bounded number of the CLI.
    """
    def check(text: str) -> _X:
        x = parse(text)
        if x < low or (strict and x == low):
            raise argparse.ArgumentTypeError(
                f'expected {kind} {">" if strict else ">="} {low:g}, got {text!r}')
        return x
    check.__name__ = check.__qualname__ = name
    check.__doc__ = (f'{summary}\n\nParameters\n----------\ntext : str\n'
                     "    The option's value as typed.\n")
    return check


positive_float = _at_least(finite_float, 0.0, True, 'a number', 'positive_float',
                           'A finite number > 0 (a bound, a delay, a duration).')
nonnegative_float = _at_least(finite_float, 0.0, False, 'a number', 'nonnegative_float',
                              'A finite number >= 0.')
positive_int = _at_least(_integer, 1, False, 'an integer', 'positive_int',
                         'An integer >= 1 (a count).')
nonnegative_int = _at_least(_integer, 0, False, 'an integer', 'nonnegative_int',
                            'An integer >= 0 (a seed).')


def add_executor_arguments(p: argparse.ArgumentParser, workers: str = '--workers') -> None:
    """``--executor local|dask`` and ``--scheduler ADDRESS`` (:mod:`.parallel`).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The sub-command's parser.
    workers : str, optional
        The command's option for the number of processes (named in the help).
    """
    p.add_argument('--executor', choices=['local', 'dask'], default='local',
                   help='where the work runs: local processes (default) or Dask distributed '
                   '(optional dependency: pip install dask distributed)')
    p.add_argument('--scheduler', metavar='ADDRESS',
                   help='with --executor dask: a running scheduler, e.g. tcp://host:8786 '
                   f'(default: a local cluster of {workers} processes)')
