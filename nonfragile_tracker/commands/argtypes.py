"""argparse ``type=`` functions for numbers: a bad value is a usage error (exit 2).

Each raises :class:`argparse.ArgumentTypeError`, so argparse prints the usage line
and ``error: argument --x: ...`` naming the option and the value.
"""
from __future__ import annotations

import argparse
import math

__all__ = ['finite_float', 'positive_float', 'nonnegative_float']


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
