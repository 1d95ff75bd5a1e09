"""Errors of the ``nodes`` package, under the package's root error.

:class:`StartupError` is an :class:`~nonfragile_tracker.errors.InputError` (a
:class:`ValueError`, exit code 2): a node refuses to start with its parameters, and the
message says which and why.  A node that fails while running ends with the exit code of
:class:`~nonfragile_tracker.errors.RunError` (5, the plant's lockstep abort) through its
``exit_code`` (:class:`~nonfragile_tracker.nodes.common.AdapterNode`).  No ROS import here:
the classes are importable (and catchable) without rclpy.  They stay importable from
:mod:`nonfragile_tracker.nodes.common`, where the nodes have always taken them.
"""
from __future__ import annotations

from ..errors import InputError

__all__ = ['StartupError']


class StartupError(InputError):
    """A node cannot start with its parameters; the message says which and why."""
