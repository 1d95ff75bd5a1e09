"""The simulation's errors: bad plant, tracker, path, trajectory, gain or batch settings.

All are bad input (:class:`nonfragile_tracker.errors.InputError`, a ``ValueError``; the CLI
exits 2), each message naming the setting and what to do: :class:`PathError` (an unknown
path name or invalid path parameter), :class:`TrajectoryError` (a trajectory cannot be built
from the given points), :class:`LoopConfigError` (a plant, tracker or gain setting, a gain
file) and :class:`BatchError` (a batch setting invalid or not supported).

See doc/cli.md, section "Exit codes and errors".
"""
from __future__ import annotations

from ...errors import InputError

__all__ = ['PathError', 'TrajectoryError', 'LoopConfigError', 'BatchError']


class PathError(InputError):
    """Unknown path name or invalid path parameter."""


class TrajectoryError(InputError):
    """A trajectory cannot be built from the given points.

    The message names the source, the index and the value.
    """


class LoopConfigError(InputError):
    """A plant, tracker or gain setting is invalid; the message names it.

    A bad gain file is a bad tracker configuration: the tracker node catches
    ``LoopConfigError`` for both.
    """


class BatchError(InputError):
    """A batch setting is invalid or not supported; the message names it."""
