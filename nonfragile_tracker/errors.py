"""The package's root error, its input and run errors, and the exit code each kind maps to.

Every error the package raises on purpose derives from :class:`NonfragileError` and from
the builtin that matches its meaning (:class:`InputError` is a ``ValueError``, exit 2;
:class:`RunError` a ``RuntimeError``, exit 5; the LMI errors live in
:mod:`nonfragile_tracker.control.synthesis.errors`); each part keeps its own errors in its
``errors`` module under these, and :func:`exit_code` is the one place that maps an
exception to a process exit code.  No ROS import here.

See doc/cli.md, section "Exit codes and errors" (the hierarchy and the codes).
"""
from __future__ import annotations

__all__ = ['NonfragileError', 'InputError', 'RunError', 'exit_code', 'EXIT_OK', 'EXIT_DIFFERENT',
           'EXIT_BAD_INPUT', 'EXIT_INFEASIBLE', 'EXIT_SOLVER', 'EXIT_RUN', 'EXIT_INTERRUPTED']

EXIT_OK = 0
#: A comparison (golden bags, ``bag compare``) found differences.
EXIT_DIFFERENT = 1
EXIT_BAD_INPUT = 2
EXIT_INFEASIBLE = 3
EXIT_SOLVER = 4
EXIT_RUN = 5
#: Ctrl-C (128 + SIGINT), as a shell reports it.
EXIT_INTERRUPTED = 130


class NonfragileError(Exception):
    """Root of every error this package raises on purpose; ``exit_code`` for the CLI."""

    exit_code: int = 1


class InputError(NonfragileError, ValueError):
    """Bad input: a file, parameter, number or message; the text says what and what to do."""

    exit_code = EXIT_BAD_INPUT


class RunError(NonfragileError, RuntimeError):
    """A run of the nodes failed (a node died, lockstep timed out)."""

    exit_code = EXIT_RUN


def exit_code(exc: BaseException) -> int:
    """The process exit code for ``exc``: its class's ``exit_code``; bad OS input is 2.

    ``FileNotFoundError``/``FileExistsError``/``IsADirectoryError``/``PermissionError``
    raised by ``open`` on a user's path are bad input (2); ``KeyboardInterrupt`` is
    130; anything else is a bug, 1 (the CLI then prints a short report, no traceback).

    Parameters
    ----------
    exc : BaseException
        The exception that ends the process.

    Returns
    -------
    int
    """
    if isinstance(exc, NonfragileError):
        return int(exc.exit_code)
    if isinstance(exc, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(exc, (FileNotFoundError, FileExistsError, IsADirectoryError,
                        NotADirectoryError, PermissionError)):
        return EXIT_BAD_INPUT
    return 1
