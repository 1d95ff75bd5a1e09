"""argparse ``type=`` functions for numbers: a bad value is a usage error (exit 2).

Each raises :class:`argparse.ArgumentTypeError`, so argparse prints the usage line
and ``error: argument --x: ...`` naming the option and the value.
"""
from __future__ import annotations

import argparse
import math

__all__ = ['finite_float', 'positive_float', 'nonnegative_float', 'positive_int',
           'nonnegative_int', 'add_executor_arguments']


def finite_float(text: str) -> float:
    """A finite real number (no ``nan``/``inf``)."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f'expected a finite number, got {text!r}')
    return x


def positive_float(text: str) -> float:
    """A finite number > 0 (a bound, a delay, a duration)."""
    x = finite_float(text)
    if x <= 0:
        raise argparse.ArgumentTypeError(f'expected a number > 0, got {text!r}')
    return x


def nonnegative_float(text: str) -> float:
    """A finite number >= 0."""
    x = finite_float(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f'expected a number >= 0, got {text!r}')
    return x


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None


def positive_int(text: str) -> int:
    """An integer >= 1 (a count)."""
    n = _integer(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f'expected an integer >= 1, got {text!r}')
    return n


def nonnegative_int(text: str) -> int:
    """An integer >= 0 (a seed)."""
    n = _integer(text)
    if n < 0:
        raise argparse.ArgumentTypeError(f'expected an integer >= 0, got {text!r}')
    return n


def add_executor_arguments(p: argparse.ArgumentParser) -> None:
    """``--executor local|dask`` and ``--scheduler ADDRESS`` (:mod:`..parallel`).

    Parameters
    ----------
    p : argparse.ArgumentParser
        The sub-command's parser.
    """
    p.add_argument('--executor', choices=['local', 'dask'], default='local',
                   help='where the work runs: local processes (default) or Dask distributed '
                   '(optional dependency: pip install dask distributed)')
    p.add_argument('--scheduler', metavar='ADDRESS',
                   help='with --executor dask: a running scheduler, e.g. tcp://host:8786 '
                   '(default: a local cluster of --jobs/--workers processes)')
