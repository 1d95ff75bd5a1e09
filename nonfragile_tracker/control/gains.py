"""The tracker's gain parameter format: one reader, one writer, one check.

A gain file is a ROS 2 parameter file for the ``tracker`` node (in any namespace)::

    /**/tracker:
      ros__parameters:
        K: [-4.4453, -4.8047, ...]   # row-major, doubles
        K_shape: [2, 4]

Values are always written as floats (a YAML ``[1, 0, ...]`` would be an
INTEGER_ARRAY, which a DOUBLE_ARRAY parameter rejects).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from ..files import read_yaml
from .loop import LoopConfigError, validate_gain

__all__ = ['GainFileError', 'gain_from_parameters', 'gain_parameters', 'write_gain_file',
           'read_gain_file', 'TRACKER_NODE']

TRACKER_NODE = 'tracker'


class GainFileError(LoopConfigError):
    """A gain file or gain parameter is malformed; the message says which and why.

    A bad gain is a bad tracker configuration: :func:`validate_gain`'s
    ``LoopConfigError`` passes through :func:`gain_from_parameters` unchanged and the
    tracker node catches ``LoopConfigError`` for both.
    """


def gain_from_parameters(flat: Sequence[Any], shape: Sequence[Any] = (2, 4)) -> np.ndarray:
    """Build and validate ``K`` from the flat row-major list and its shape."""
    try:
        shp = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise GainFileError(f'K_shape must be two integers [rows, cols], got {shape!r}') from None
    if len(shp) != 2 or min(shp) <= 0:
        raise GainFileError(f'K_shape must be two positive integers [rows, cols], got {shape!r}')
    if isinstance(flat, (str, bytes)) or not hasattr(flat, '__len__'):
        raise GainFileError(f'K must be a list of numbers (row-major), got {flat!r}')
    for i, val in enumerate(flat):
        if isinstance(val, bool) or not isinstance(val, (int, float, np.floating, np.integer)):
            raise GainFileError(f'K[{i}] is {val!r}; every entry must be a number')
    return validate_gain(list(flat), shape=shp)


def gain_parameters(K) -> dict[str, list]:
    """``{'K': [...floats...], 'K_shape': [rows, cols]}`` for a gain matrix."""
    K = np.asarray(K, dtype=float)
    return {'K': [float(v) for v in K.ravel()], 'K_shape': [int(s) for s in K.shape]}


def write_gain_file(path: str | os.PathLike, K, *, comment: str = '', overwrite: bool = False,
                    extra: dict[str, Any] | None = None) -> Path:
    """Write the tracker parameter file; refuses to replace an existing file unless asked."""
    path = Path(path)
    params = gain_parameters(K)
    params.update(extra or {})
    text = ''.join(f'# {line}\n' for line in comment.splitlines())
    text += yaml.safe_dump({f'/**/{TRACKER_NODE}': {'ros__parameters': params}},
                           default_flow_style=None, sort_keys=False)
    mode = 'w' if overwrite else 'x'
    try:
        with open(path, mode) as fh:
            fh.write(text)
    except FileExistsError:
        raise FileExistsError(f'{path} exists; pass --force to overwrite it') from None
    return path


def read_gain_file(path: str | os.PathLike, node: str = TRACKER_NODE) -> np.ndarray:
    """Read ``K`` from a tracker parameter file (``node`` or ``/**`` section)."""
    path = Path(path)
    data = read_yaml(path, 'gain file', error=GainFileError)
    if not isinstance(data, dict):
        got = 'an empty file' if data is None else f'a {type(data).__name__}'
        raise GainFileError(f'{path}: expected a ROS 2 parameter file with a "{node}" section, '
                            f'got {got}')
    for key in (f'/**/{node}', node, f'/{node}', '/**'):
        section = data.get(key)
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict) \
                and 'K' in section['ros__parameters']:
            params = section['ros__parameters']
            try:
                return gain_from_parameters(params['K'], params.get('K_shape', (2, 4)))
            except LoopConfigError as exc:        # add the file's name
                raise GainFileError(f'{path}: {exc}') from None
    raise GainFileError(f'{path}: no {node}.ros__parameters.K found')
