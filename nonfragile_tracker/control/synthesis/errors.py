"""The synthesis's errors: a malformed problem, and LMI syntheses that give no certified gain.

Under the package's root error (:mod:`nonfragile_tracker.errors`), each also deriving from
the builtin of its meaning: :class:`ProblemError` (an ``InputError``, exit 2) for a problem
file or matrix that is malformed; :class:`LmiError` (a ``RuntimeError``) with
:class:`InfeasibleError` (exit 3, no certified gain exists as posed), :class:`SolverFailure`
and :class:`CertificateError` (exit 4).  The LMI errors were in
:mod:`nonfragile_tracker.errors`; the package's foundation may not import the control core,
so they live here now.

See doc/cli.md, section "Exit codes and errors".
"""
from __future__ import annotations

from ...errors import EXIT_INFEASIBLE, EXIT_SOLVER, InputError, NonfragileError

__all__ = ['ProblemError', 'LmiError', 'InfeasibleError', 'SolverFailure', 'CertificateError']


class ProblemError(InputError):
    """A synthesis problem (or a matrix in it) is malformed; the message names the field."""


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
