"""The one matrix/shape validator of the package (python-control's single shape-check helper).

Every module that takes a matrix from a user - a problem file, a node parameter, a
CLI option, a function argument - converts it here, so the message for a bad value
is the same everywhere: the name, what was wrong, and what to write instead.

See doc/cli.md, section "Exit codes and errors", and doc/developing.md, section
"Architecture rules".
"""
from __future__ import annotations

import math
from typing import Any, Sequence, cast

import numpy as np

from ..errors import InputError

__all__ = ['as_matrix', 'as_square', 'as_finite_float', 'StateInputShape']

Shape = Sequence['int | None']


def as_matrix(value: Any, name: str, shape: Shape | None = None, *,
              error: type[InputError] = InputError, flat: bool = False) -> np.ndarray:
    """Convert ``value`` (nested lists, array or scalar) to a finite real 2-D float array.

    Parameters
    ----------
    value : array_like
        Nested lists of numbers, an array, or a scalar (1x1).  With ``flat=True`` a
        flat row-major list (as ROS double-array parameters carry) of exactly
        ``shape[0] * shape[1]`` numbers.
    name : str
        What the value is, for the message (``'A_tau'``, ``'K'``, a file field).
    shape : (rows, cols), optional
        Required shape; ``None`` entries are free.  Required with ``flat=True``.
    error : subclass of InputError, optional
        The exception class to raise (a module's own, e.g. ``ProblemError``).
    flat : bool, optional
        Read ``value`` as a flat row-major list of ``shape``.

    Returns
    -------
    numpy.ndarray
        A new float array of 2 dimensions.

    Raises
    ------
    InputError
        (Or ``error``, if given.)
        Naming ``name`` for non-numeric or complex entries, ragged rows, NaN/inf,
        too many dimensions or a wrong shape.
    """
    if isinstance(value, (str, bytes)) or value is None:
        raise error(f'{name}: expected a matrix (list of rows of numbers), got {value!r}')
    try:
        raw = np.asarray(value)
        if np.iscomplexobj(raw):
            raise error(f'{name}: expected a real matrix, got complex entries')
        arr = np.array(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise error(f'{name}: expected a matrix of numbers, got {value!r} ({exc}); '
                    'write it as a list of rows, e.g. [[1.0, 0.0], [0.0, 1.0]]') from None
    if flat:
        if shape is None or None in tuple(shape):
            raise TypeError('as_matrix(flat=True) needs a full shape')
        rows, cols = int(cast(int, shape[0])), int(cast(int, shape[1]))
        if arr.ndim != 1 or arr.size != rows * cols:
            raise error(f'{name} needs {rows * cols} doubles ({rows}x{cols} row-major), '
                        f'got {arr.size}')
        arr = arr.reshape(rows, cols)
    elif arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = arr.reshape(1, -1)
    if arr.ndim != 2:
        raise error(f'{name}: expected a 2-D matrix, got an array with {arr.ndim} dimensions')
    bad = ~np.isfinite(arr)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise error(f'{name}: entry [{i}][{j}] is {arr[i, j]}; all entries must be finite')
    if shape is not None:
        for axis, (want, got) in enumerate(zip(shape, arr.shape)):
            if want is not None and want != got:
                want_txt = ', '.join('*' if s is None else str(s) for s in shape)
                raise error(f'{name}: expected shape ({want_txt}), '
                            f'got {arr.shape} (axis {axis} has {got}, needs {want})')
    return arr


def as_square(value: Any, name: str, n: int | None = None, *,
              error: type[InputError] = InputError) -> np.ndarray:
    """:func:`as_matrix` for a square matrix (of order ``n`` if given).

    Parameters
    ----------
    value : array_like
        Nested lists of numbers, an array or a scalar.
    name : str
        What the value is, for the message.
    n : int, optional
        Required order; any when ``None``.
    error : subclass of InputError, optional
        The exception class to raise.

    Returns
    -------
    numpy.ndarray, shape (n, n)

    Raises
    ------
    InputError
        (Or ``error``, if given.)
        As :func:`as_matrix`, or when the matrix is not square.
    """
    arr = as_matrix(value, name, (n, n), error=error)
    if arr.shape[0] != arr.shape[1]:
        raise error(f'{name}: expected a square matrix, got shape {arr.shape}')
    return arr


def as_finite_float(value: Any, name: str, *, low: float | None = None,
                    low_inclusive: bool = True, error: type[InputError] = InputError) -> float:
    """A finite real number (``bool`` refused), optionally ``>= low`` (or ``> low``).

    Parameters
    ----------
    value : object
        A number, or anything ``float()`` accepts (a numeric string).
    name : str
        What the value is, for the message.
    low : float, optional
        Lower bound; none when ``None``.
    low_inclusive : bool, optional
        Whether ``low`` itself is allowed.
    error : subclass of InputError, optional
        The exception class to raise.

    Returns
    -------
    float

    Raises
    ------
    InputError
        (Or ``error``, if given.)
        For a bool, a non-number, NaN or inf, or a value below the bound.
    """
    if isinstance(value, bool):
        raise error(f'{name}: expected a number, got {value!r}')
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise error(f'{name}: expected a number, got {value!r}') from None
    if not math.isfinite(x):
        raise error(f'{name}: expected a finite number, got {value!r}')
    if low is not None and (x < low or (x == low and not low_inclusive)):
        raise error(f'{name}: expected a number {">=" if low_inclusive else ">"} {low:g}, '
                    f'got {value!r}')
    return x


class StateInputShape:
    """``n`` and ``m`` of a record holding a state matrix ``A`` and an input matrix ``B``.

    A mixin of :class:`.problem.Problem` and :class:`.model.LinearizedModel` (one place
    for the dimensions they read from ``A`` (``n x n``) and ``B`` (``n x m``)).
    """

    A: np.ndarray
    B: np.ndarray

    @property
    def n(self) -> int:
        """Number of states."""
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        """Number of inputs."""
        return int(self.B.shape[1])
