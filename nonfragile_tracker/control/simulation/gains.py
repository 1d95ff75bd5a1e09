"""The tracker's gain parameter format: one reader, one writer, one check.

A gain file is a ROS 2 parameter file for the ``tracker`` node (``K`` row-major as doubles,
``K_shape``), optionally with a ``gain_design`` section no node reads that records what the
gain was designed for (:func:`read_gain_design`).

See doc/ros-interface.md, section "tracker" (the gain file).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from ...files import read_yaml
from .tracker import validate_gain
from .errors import LoopConfigError

__all__ = ['LoopConfigError', 'gain_from_parameters', 'gain_parameters', 'write_gain_file',
           'read_gain_file', 'read_gain_design', 'TRACKER_NODE', 'DESIGN_SECTION']

TRACKER_NODE = 'tracker'
#: Section of a gain file holding the design record (no node of that name exists).
DESIGN_SECTION = 'gain_design'


def gain_from_parameters(flat: Sequence[Any], shape: Sequence[Any] = (2, 4)) -> np.ndarray:
    """Build and validate ``K`` from the flat row-major list and its shape.

    Parameters
    ----------
    flat : sequence of float
        The entries of ``K``, row-major (the ``K`` parameter).
    shape : sequence of int
        ``[rows, cols]`` (the ``K_shape`` parameter).

    Returns
    -------
    numpy.ndarray

    Raises
    ------
    LoopConfigError
        A bad shape or a non-numeric entry.
        A gain the tracker refuses (:func:`.control.simulation.tracker.validate_gain`).
    """
    try:
        shp = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise LoopConfigError(f'K_shape must be two integers [rows, cols], got {shape!r}') from None
    if len(shp) != 2 or min(shp) <= 0:
        raise LoopConfigError(f'K_shape must be two positive integers [rows, cols], got {shape!r}')
    if isinstance(flat, (str, bytes)) or not hasattr(flat, '__len__'):
        raise LoopConfigError(f'K must be a list of numbers (row-major), got {flat!r}')
    for i, val in enumerate(flat):
        if isinstance(val, bool) or not isinstance(val, (int, float, np.floating, np.integer)):
            raise LoopConfigError(f'K[{i}] is {val!r}; every entry must be a number')
    return validate_gain(list(flat), shape=shp)


def gain_parameters(K: Any) -> dict[str, list[Any]]:
    """``{'K': [...floats...], 'K_shape': [rows, cols]}`` for a gain matrix.

    Parameters
    ----------
    K : array_like, 2-D
        The gain.

    Returns
    -------
    dict
    """
    K = np.asarray(K, dtype=float)
    return {'K': [float(v) for v in K.ravel()], 'K_shape': [int(s) for s in K.shape]}


def _design_value(key: str, value: Any) -> Any:
    """A design-record value as a ROS parameter can hold it (no None, no mixed lists)."""
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    if isinstance(value, (list, tuple)) and value and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            for v in value):
        return [float(v) for v in value]
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, str) for v in value):
        return list(value)
    raise LoopConfigError(f'design record {key!r}: {value!r} is not a number, string, bool or '
                          'a non-empty list of numbers or strings')


def write_gain_file(path: str | os.PathLike[str], K: Any, *, comment: str = '',
                    overwrite: bool = False, extra: dict[str, Any] | None = None,
                    design: dict[str, Any] | None = None) -> Path:
    """Write the tracker parameter file; refuses to replace an existing file unless asked.

    Parameters
    ----------
    path : path-like
        File to write.
    K : array_like
        The gain.
    comment : str
        Written as ``#`` lines at the top.
    overwrite : bool
        Replace an existing file.
    extra : dict, optional
        More tracker parameters.
    design : dict, optional
        What the gain was designed for (flat mapping of numbers, strings, bools and
        lists of numbers), written to the :data:`DESIGN_SECTION` section.
    """
    path = Path(path)
    params = gain_parameters(K)
    params.update(extra or {})
    text = ''.join(f'# {line}\n' for line in comment.splitlines())
    text += yaml.safe_dump({f'/**/{TRACKER_NODE}': {'ros__parameters': params}},
                           default_flow_style=None, sort_keys=False)
    if design:
        record = {str(k): _design_value(str(k), v) for k, v in design.items()}
        text += yaml.safe_dump({DESIGN_SECTION: {'ros__parameters': record}},
                               default_flow_style=False, sort_keys=False, width=100)
    mode = 'w' if overwrite else 'x'
    try:
        with open(path, mode) as fh:
            fh.write(text)
    except FileExistsError:
        raise FileExistsError(f'{path} exists; pass --force to overwrite it') from None
    return path


def read_gain_file(path: str | os.PathLike[str], node: str = TRACKER_NODE) -> np.ndarray:
    """Read ``K`` from a tracker parameter file (``node`` or ``/**`` section).

    Parameters
    ----------
    path : str or os.PathLike
        The parameter file.
    node : str
        The node section to read (a ``/**`` section also counts).

    Returns
    -------
    numpy.ndarray

    Raises
    ------
    LoopConfigError
        The file cannot be read, has no such section or ``K``, or ``K`` is invalid.
    """
    path = Path(path)
    return gain_from_file_data(read_yaml(path, 'gain file', error=LoopConfigError), path, node)


def gain_from_file_data(data: Any, path: str | os.PathLike[str],
                        node: str = TRACKER_NODE) -> np.ndarray:
    """``K`` from a parameter file's parsed content (:func:`read_gain_file` after the read).

    For a caller that has read the file already for its other parameters; the result and
    the :class:`.LoopConfigError` for a content without ``K`` are those of
    :func:`read_gain_file`.

    Parameters
    ----------
    data : object
        The file's YAML content.
    path, node
        The file (named in the errors) and the section, as in :func:`read_gain_file`.

    Returns
    -------
    numpy.ndarray
    """
    if not isinstance(data, dict):
        got = 'an empty file' if data is None else f'a {type(data).__name__}'
        raise LoopConfigError(f'{path}: expected a ROS 2 parameter file with a "{node}" section, '
                              f'got {got}')
    for key in (f'/**/{node}', node, f'/{node}', '/**'):
        section = data.get(key)
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict) \
                and 'K' in section['ros__parameters']:
            params = section['ros__parameters']
            try:
                return gain_from_parameters(params['K'], params.get('K_shape', (2, 4)))
            except LoopConfigError as exc:        # add the file's name
                raise LoopConfigError(f'{path}: {exc}') from None
    raise LoopConfigError(f'{path}: no {node}.ros__parameters.K found')


def read_gain_design(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The design record of a gain file (see module docstring), ``None`` if it has none.

    Parameters
    ----------
    path : str or os.PathLike
        The gain file.

    Returns
    -------
    dict or None

    Raises
    ------
    LoopConfigError
        The file cannot be read, is not YAML, or the record is not a mapping.
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise LoopConfigError(f'{path}: cannot read gain file ({exc.strerror})') from None
    except yaml.YAMLError as exc:
        raise LoopConfigError(f'{path}: not valid YAML ({exc})') from None
    section = data.get(DESIGN_SECTION) if isinstance(data, dict) else None
    if not isinstance(section, dict):
        return None
    params = section.get('ros__parameters')
    if not isinstance(params, dict):
        raise LoopConfigError(f'{path}: section {DESIGN_SECTION!r} has no ros__parameters mapping')
    return dict(params)
