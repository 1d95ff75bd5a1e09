"""Errors of the ``bag`` package, one hierarchy under :class:`BagError`.

Every class is an :class:`~nonfragile_tracker.errors.InputError` (a :class:`ValueError`,
exit code 2); some also derive from the builtin of their meaning
(:class:`FileExistsError`, :class:`FileNotFoundError`).  The message says what was wrong
and what to do.
"""
from __future__ import annotations

from collections.abc import Iterable

from ..errors import InputError

__all__ = ['BagError', 'BagExistsError', 'InvalidRunNameError', 'BagNotFoundError',
           'NotABagError', 'BagTruncatedError', 'MissingTopicsError', 'RepairError',
           'NothingToRepairError', 'ToleranceError']


class BagError(InputError):
    """A bag cannot be written, read, repaired or reported; the message says what to do."""


class BagExistsError(BagError, FileExistsError):
    """The target bag directory exists already; bags are never overwritten."""


class InvalidRunNameError(BagError, ValueError):
    """A run directory name would escape its root (path separator, ``..``) or is empty."""


class BagNotFoundError(BagError, FileNotFoundError):
    """The bag directory does not exist."""


class NotABagError(BagError):
    """The path exists but is not a readable rosbag2 bag."""


class BagTruncatedError(BagError):
    """An MCAP file was never closed (recorder killed); it needs ``bag repair``."""


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


class RepairError(BagError):
    """A bag cannot be repaired; the message says why."""


class NothingToRepairError(RepairError):
    """The bag is complete (closed MCAP and metadata.yaml); read it directly."""


class ToleranceError(BagError):
    """A ``--tol`` rule cannot be parsed; the message shows the expected form."""
