"""The package's one exception hierarchy and the exit code each kind maps to.

Every error the package raises on purpose derives from :class:`NonfragileError`
and from the builtin that matches its meaning (as python-control does), so a
caller can catch ``ValueError`` for bad input without knowing this module::

    NonfragileError                      exit 1
    +-- InputError (ValueError)          exit 2  bad file, parameter, number or message
    +-- LmiError (RuntimeError)
    |   +-- InfeasibleError              exit 3  no certified gain exists (as posed)
    |   +-- SolverFailure                exit 4  solver missing or no usable status
    |   +-- CertificateError             exit 4  a solver point failed independent verification
    +-- RunError (RuntimeError)          exit 5  a run (nodes, lockstep) failed

Domain modules subclass these (``ProblemError(InputError)``, ``BagError(InputError)``
...); :func:`exit_code` is the one place that maps an exception to a process exit
code.  No ROS import here.
"""
from __future__ import annotations

__all__ = ['NonfragileError', 'InputError', 'LmiError', 'InfeasibleError', 'SolverFailure',
           'CertificateError', 'RunError', 'exit_code', 'EXIT_OK', 'EXIT_DIFFERENT',
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


class LmiError(NonfragileError, RuntimeError):
    """Base class of LMI synthesis failures."""

    exit_code = EXIT_SOLVER


class InfeasibleError(LmiError):
    """The LMI has no strictly feasible point with the requested margin."""

    exit_code = EXIT_INFEASIBLE
    #: the best strictness t found (set by the input-delay synthesis; not always present)
    margin_achieved: float


class SolverFailure(LmiError):
    """The solver is missing or returned no usable status."""

    exit_code = EXIT_SOLVER


class CertificateError(LmiError):
    """A solver result failed the independent numpy verification."""

    exit_code = EXIT_SOLVER
    #: the solver's strictness t, set by the Theorem 1 synthesis (not always present)
    margin_achieved: float


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
