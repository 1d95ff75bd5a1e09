"""Reading the package's YAML files (problems, gains, scenarios) with one kind of message.

A missing file, a directory, binary junk, a file that is not YAML or that holds the
wrong kind of document becomes an :class:`~nonfragile_tracker.errors.InputError`
(or the caller's subclass) naming the file and what was wrong - never a traceback.

See doc/cli.md, section "Exit codes and errors".
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from .errors import InputError

__all__ = ['node_key', 'read_yaml']


def read_yaml(path: str | os.PathLike[str], what: str, *, error: type[InputError] = InputError,
              mapping: bool = False) -> Any:
    """Parse the YAML file ``path``; any problem is ``error`` naming the file.

    Parameters
    ----------
    path : path-like
        The file to read.
    what : str
        What the file is, for the message (``'problem file'``, ``'gain file'``).
    error : subclass of InputError
        The exception class to raise.
    mapping : bool
        Require a mapping at the top (an empty file then is an error too).

    Returns
    -------
    object
        The parsed document (``None`` for an empty file unless ``mapping``).

    Raises
    ------
    InputError
        (Or ``error``, if given.)
        The file cannot be read (missing, a directory, no permission), is not UTF-8
        text, is not valid YAML, or (``mapping=True``) is not a mapping.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise error(f'{path}: cannot read {what} ({exc.strerror or exc})') from None
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise error(f'{path}: not a text file (byte {exc.start} is not UTF-8); '
                    f'expected a YAML {what}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'line {mark.line + 1}, column {mark.column + 1}: ' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
        raise error(f'{path}: not valid YAML ({where}{problem}); expected a YAML {what}') \
            from None
    if mapping and not isinstance(data, dict):
        got = 'an empty file' if data is None else f'a {type(data).__name__}'
        raise error(f'{path}: expected a YAML mapping ({what}), got {got}')
    return data


def node_key(key: str) -> str:
    """Node name of a ROS 2 parameter-file key.

    Parameters
    ----------
    key : str
        A top-level key of a parameter file: ``tracker``, ``/tracker`` or ``/**/tracker``.

    Returns
    -------
    str
        The bare node name (``tracker``).
    """
    for prefix in ('/**/', '/'):
        if key.startswith(prefix):
            return key[len(prefix):]
    return key
