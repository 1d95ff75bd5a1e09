"""The identification's errors: a run that gives no estimate, a bad file or monitor setting.

All are bad input (:class:`nonfragile_tracker.errors.InputError`, a ``ValueError``; the
CLI exits 2), each message saying what is missing or wrong::

    InputError
    +-- IdentificationError                 the run cannot give a latency estimate
    |   +-- NotEnoughDataError              too few samples or too short an overlap
    |   +-- InsufficientExcitationError     a channel's command hardly varies
    |   +-- PoorFitError                    the model does not explain the motion
    |   +-- IdentificationFileError         an identification file is malformed
    +-- MonitorError                        a monitor setting or certificate record
"""
from __future__ import annotations

from ...errors import InputError

__all__ = ['IdentificationError', 'NotEnoughDataError', 'InsufficientExcitationError',
           'PoorFitError', 'IdentificationFileError', 'MonitorError']


class IdentificationError(InputError):
    """The run cannot give a latency estimate; the message says what is missing."""


class NotEnoughDataError(IdentificationError):
    """Too few samples, or commands and odometry overlap too briefly."""


class InsufficientExcitationError(IdentificationError):
    """A channel's command hardly varies, so its lag and the latency are not observable."""


class PoorFitError(IdentificationError):
    """The FOPDT model does not explain the measured motion, or hits a search limit."""


class IdentificationFileError(IdentificationError):
    """An identification file is malformed; the message names the field."""


class MonitorError(InputError):
    """A monitor setting or certificate record is invalid; the message names it."""
