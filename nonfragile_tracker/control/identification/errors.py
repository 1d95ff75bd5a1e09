"""The identification's errors: a run that gives no estimate, a bad file or monitor setting.

All are bad input (:class:`nonfragile_tracker.errors.InputError`, a ``ValueError``; the
CLI exits 2), each message saying what is missing or wrong::

    InputError
    +-- IdentificationError     the run cannot give a latency estimate (too few samples,
    |                           too little excitation, a poor fit) or a file is malformed
    +-- MonitorError            a monitor setting or certificate record
"""
from __future__ import annotations

from ...errors import InputError

__all__ = ['IdentificationError', 'MonitorError']


class IdentificationError(InputError):
    """The run cannot give a latency estimate, or an identification file is malformed.

    The message says what is missing (too few samples, too little excitation, a poor fit)
    or names the field.
    """


class MonitorError(InputError):
    """A monitor setting or certificate record is invalid; the message names it."""
