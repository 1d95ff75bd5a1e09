"""The identification's errors: a run that gives no estimate, a bad file or monitor setting.

All are bad input (:class:`nonfragile_tracker.errors.InputError`, a ``ValueError``; the CLI
exits 2), each message saying what is missing or wrong: :class:`IdentificationError` (the
run cannot give a latency estimate, or a file is malformed) with :class:`NotEnoughDataError`,
:class:`InsufficientExcitationError` and :class:`PoorFitError`, and :class:`MonitorError`
(a monitor setting or certificate record).

See doc/cli.md, section "Exit codes and errors", and doc/tutorial.md, section "Identify
the latency (``identify``)" (the refusals).
"""
from __future__ import annotations

from ...errors import InputError

__all__ = ['IdentificationError', 'NotEnoughDataError', 'InsufficientExcitationError',
           'PoorFitError', 'MonitorError']


class IdentificationError(InputError):
    """The run cannot give a latency estimate, or an identification file is malformed.

    The message says what is missing (too few samples, too little excitation, a poor fit)
    or names the field.
    """


class NotEnoughDataError(IdentificationError):
    """Too few commands or odometry samples, or too short an overlap, to estimate from.

    Caught by the bring-up
    (:func:`~nonfragile_tracker.workflows.commissioning.identify_samples`), which says what to
    change.
    """


class InsufficientExcitationError(IdentificationError):
    """A command channel hardly varies: the data cannot show a latency (bring-up: a larger box)."""


class PoorFitError(IdentificationError):
    """The model explains too little of the response, or an estimate is at a search limit."""


class MonitorError(InputError):
    """A monitor setting or certificate record is invalid; the message names it."""
