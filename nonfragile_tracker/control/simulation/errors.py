"""The simulation's errors: bad plant, tracker, path, trajectory, gain or batch settings.

All are bad input (:class:`nonfragile_tracker.errors.InputError`, a ``ValueError``; the
CLI exits 2), each message naming the setting and what to do::

    InputError
    +-- SingularSpeedError      the linearizing map at (or too near) v = 0
    +-- PathError               unknown path name or invalid path parameter
    +-- TrajectoryError         a trajectory cannot be built from the given points
    +-- LoopConfigError         a plant or tracker setting is invalid
    |   +-- GainFileError       a gain file or gain parameter is malformed
    +-- BatchError              a batch setting is invalid or not supported
"""
from __future__ import annotations

from ...errors import InputError

__all__ = ['SingularSpeedError', 'PathError', 'TrajectoryError', 'LoopConfigError',
           'GainFileError', 'BatchError']


class SingularSpeedError(InputError):
    """Raised when the linearizing map is evaluated at (or too near) ``v = 0``."""


class PathError(InputError):
    """Unknown path name or invalid path parameter."""


class TrajectoryError(InputError):
    """A trajectory cannot be built from the given points.

    The message names the source, the index and the value.
    """


class LoopConfigError(InputError):
    """A plant or tracker setting is invalid; the message names the setting."""


class GainFileError(LoopConfigError):
    """A gain file or gain parameter is malformed; the message says which and why.

    A bad gain is a bad tracker configuration: :func:`~.loop.validate_gain`'s
    ``LoopConfigError`` passes through :func:`~.gains.gain_from_parameters` unchanged and
    the tracker node catches ``LoopConfigError`` for both.
    """


class BatchError(InputError):
    """A batch setting is invalid or not supported; the message names it."""
