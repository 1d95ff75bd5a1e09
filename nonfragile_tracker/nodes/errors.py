"""Errors of the ``nodes`` package, under the package's root error.

:class:`StartupError` is an :class:`~nonfragile_tracker.errors.InputError` (a
:class:`ValueError`, exit code 2): a node refuses to start with its parameters, and the
message says which and why.  A node that fails while running ends with the exit code of
:class:`~nonfragile_tracker.errors.RunError` (5, the plant's lockstep abort) through its
``exit_code`` (:class:`~nonfragile_tracker.nodes.common.AdapterNode`).  No ROS import here:
the classes are importable (and catchable) without rclpy.  They stay importable from
:mod:`nonfragile_tracker.nodes.common`, where the nodes have always taken them.

See doc/cli.md, section "Exit codes and errors", and doc/safety.md.
"""
from __future__ import annotations

from ..errors import InputError, NonfragileError

__all__ = ['StartupError', 'StartupStopped']


class StartupError(InputError):
    """A node cannot start with its parameters; the message says which and why."""


class StartupStopped(NonfragileError):
    """A stop signal came while a node was starting: it ends its start-up (exit code 0).

    Raised by :meth:`~nonfragile_tracker.nodes.common.AdapterNode.check_stop` between the
    pieces of a long start-up (the reference's trajectory of an hour); ``run`` ends the
    process with 0 as for any signal during start-up.
    """

    exit_code = 0
