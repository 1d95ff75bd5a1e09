"""Errors of the ``bag`` package, under :class:`BagError`.

Every class is an :class:`~nonfragile_tracker.errors.InputError` (a :class:`ValueError`,
exit code 2); a subclass exists where a caller tells it apart: by the builtin of its
meaning (:class:`FileExistsError`, :class:`FileNotFoundError`) or by what it carries (the
missing topics).  The message says what was wrong and what to do.

See doc/cli.md, section "Exit codes and errors".
"""
from __future__ import annotations

from collections.abc import Iterable

from ..errors import InputError

__all__ = ['BagError', 'BagExistsError', 'BagNotFoundError', 'MissingTopicsError']


class BagError(InputError):
    """A bag cannot be written, read, repaired, compared or reported.

    The message says what and what to do (a bag that is not one, an MCAP never closed, a
    bad ``--tol`` rule, ...).
    """


class BagExistsError(BagError, FileExistsError):
    """The target bag directory exists already; bags are never overwritten."""


class BagNotFoundError(BagError, FileNotFoundError):
    """The bag directory does not exist."""


class MissingTopicsError(BagError):
    """The bag lacks topics that are needed; ``missing`` names them.

    Parameters
    ----------
    message : str
        What is missing and what to do.
    missing : iterable of str, optional
        The missing topics (kept as the tuple ``missing``).
    """

    def __init__(self, message: str, missing: Iterable[str] = ()) -> None:
        super().__init__(message)
        self.missing = tuple(missing)
