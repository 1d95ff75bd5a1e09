"""Objectives on top of Theorem 1: each a bisection over the convex synthesis LMI.

:func:`max_perturbation_scale` (largest scale ``s`` of ``F``), :func:`max_decay_rate`
(largest certified decay rate ``alpha``) and :func:`min_gain_norm` (smallest gain bound
``kappa``); the gain returned is the one synthesized at the last feasible point, with its
verified certificate (:func:`.lmi.synthesize` verifies every solve).

See doc/cli.md, section "design" (each objective, why bisection finds it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .lmi import SynthesisResult, synthesize
from .errors import InfeasibleError, LmiError
from .problem import Problem
from .search import largest_feasible

__all__ = ['DesignResult', 'max_perturbation_scale', 'max_decay_rate', 'min_gain_norm',
           'shifted_problem', 'at_gain_norm']


@dataclass(frozen=True)
class DesignResult:
    """The optimized value and the verified synthesis at that value."""

    objective: str
    value: float
    synthesis: SynthesisResult
    problem: Problem           # the problem actually certified (scaled F, shifted A, ...)
    solves: int

    @property
    def K(self) -> np.ndarray:
        """The designed gain (the synthesis result's ``K``)."""
        return self.synthesis.K


def shifted_problem(problem: Problem, alpha: float) -> Problem:
    """``A + alpha I`` and ``e^{alpha tau} A_tau``: Theorem 1 on it certifies decay rate alpha.

    Parameters
    ----------
    problem : Problem
        The problem to shift.
    alpha : float
        The decay rate [1/s].

    Returns
    -------
    Problem
        A copy of ``problem`` with the shifted ``A`` and ``A_tau``.
    """
    return problem.replace(A=problem.A + alpha * np.eye(problem.n),
                           A_tau=math.exp(alpha * problem.tau) * problem.A_tau)


def _try(problem: Problem, **kw: Any) -> SynthesisResult | None:
    try:
        return synthesize(problem, **kw)
    except InfeasibleError:
        return None
    except LmiError:            # numerical trouble at an extreme trial value: not certified
        return None


def max_perturbation_scale(problem: Problem, *, gain_bound: float, rel_tol: float = 1e-3,
                           hi_limit: float = 1e3) -> DesignResult:
    """Largest ``s`` with Theorem 1 feasible for ``F -> s F`` and ``||K||_2 <= gain_bound``.

    Parameters
    ----------
    problem : Problem
        The problem whose ``F`` is scaled.
    gain_bound : float
        The LMI bound on ``||K||_2``.
    rel_tol : float, optional
        Relative tolerance of the bisection on ``s``.
    hi_limit : float, optional
        Largest ``s`` tried.

    Returns
    -------
    DesignResult
        ``value`` is ``s``; ``problem`` has ``F`` scaled by it.

    Raises
    ------
    InfeasibleError
        If Theorem 1 is infeasible under the gain bound even without perturbation.
    """
    def feas(s: float) -> SynthesisResult | None:
        return _try(problem.replace(F=s * problem.F), gain_bound=gain_bound)

    base = feas(1e-9)
    if base is None:
        raise InfeasibleError(f'Theorem 1 is infeasible for {problem.name!r} with '
                              f'||K||_2 <= {gain_bound:g} even without perturbation')
    s, best, n = largest_feasible(feas, 1e-9, 1.0, rel_tol=rel_tol, hi_limit=hi_limit,
                                  lo_result=base)
    return DesignResult('max_perturbation_scale', s, best, problem.replace(F=s * problem.F),
                        n + 1)


def max_decay_rate(problem: Problem, *, gain_bound: float, nominal: bool = False,
                   rel_tol: float = 1e-3, hi_limit: float = 1e3) -> DesignResult:
    """Largest certified decay rate ``alpha >= 0`` under ``||K||_2 <= gain_bound``.

    Parameters
    ----------
    problem : Problem
        The problem to shift (:func:`shifted_problem`).
    gain_bound : float
        The LMI bound on ``||K||_2``.
    nominal : bool, optional
        Certify the nominal loop (``D = 0``) instead of the non-fragile one.
    rel_tol : float, optional
        Relative tolerance of the bisection on ``alpha``.
    hi_limit : float, optional
        Largest ``alpha`` tried [1/s].

    Returns
    -------
    DesignResult
        ``value`` is ``alpha`` [1/s]; ``problem`` is the shifted problem.

    Raises
    ------
    InfeasibleError
        If Theorem 1 is infeasible under the gain bound at ``alpha = 0``.
    """
    def feas(a: float) -> SynthesisResult | None:
        return _try(shifted_problem(problem, a), gain_bound=gain_bound, nominal=nominal)

    base = feas(0.0)
    if base is None:
        raise InfeasibleError(f'Theorem 1 is infeasible for {problem.name!r} with '
                              f'||K||_2 <= {gain_bound:g}: no decay rate is certified')
    a, best, n = largest_feasible(feas, 0.0, 0.5, rel_tol=rel_tol, hi_limit=hi_limit,
                                  lo_result=base)
    return DesignResult('max_decay_rate', a, best, shifted_problem(problem, a), n + 1)


def min_gain_norm(problem: Problem, *, nominal: bool = False, rel_tol: float = 1e-3,
                  hi: float = 1e3) -> DesignResult:
    """Smallest ``kappa`` such that Theorem 1 is feasible with ``||K||_2 <= kappa``.

    Parameters
    ----------
    problem : Problem
        The problem.
    nominal : bool, optional
        Certify the nominal loop (``D = 0``) instead of the non-fragile one.
    rel_tol : float, optional
        Relative tolerance of the bisection on ``kappa``.
    hi : float, optional
        Largest ``kappa`` tried (the first solve).

    Returns
    -------
    DesignResult
        ``value`` is ``kappa``.

    Raises
    ------
    InfeasibleError
        If Theorem 1 is infeasible even with ``||K||_2 <= hi``.
    """
    best = _try(problem, gain_bound=hi, nominal=nominal)
    if best is None:
        raise InfeasibleError(f'Theorem 1 is infeasible for {problem.name!r} even with '
                              f'||K||_2 <= {hi:g}')
    lo, solves = 0.0, 1
    while hi - lo > rel_tol * hi:
        mid = 0.5 * (lo + hi)
        r = _try(problem, gain_bound=mid, nominal=nominal)
        solves += 1
        if r is None:
            lo = mid
        else:
            hi, best = mid, r
    return DesignResult('min_gain_norm', hi, best, problem, solves)


def at_gain_norm(design: Callable[..., DesignResult], problem: Problem, norm: float, *,
                 rel_tol: float = 2e-3, **kw: Any) -> DesignResult:
    """Run ``design`` with the largest LMI gain bound whose gain has ``||K||_2 <= norm``.

    ``design(problem, gain_bound=kappa, **kw)`` is run with the largest LMI bound ``kappa``
    whose gain still has ``||K||_2 <= norm``.
    The LMI form of the gain bound (``X >= I``, ``R^T R <= kappa^2 (2X - I)``) is
    conservative: the realized ``||K||_2`` is often well below ``kappa``.  This outer
    bisection over ``kappa`` in ``[norm, 4 norm]`` spends the whole budget ``norm``.

    Parameters
    ----------
    design : callable
        A design function such as :func:`max_decay_rate`, called as
        ``design(problem, gain_bound=kappa, **kw)``.
    problem : Problem
        The problem passed to ``design``.
    norm : float
        The budget on the realized ``||K||_2``.
    rel_tol : float, optional
        Relative tolerance of the bisection on ``kappa``.
    **kw
        Further keyword arguments of ``design``.

    Returns
    -------
    DesignResult
        The result at the largest ``kappa`` found whose gain has ``||K||_2 <= norm``
        (that of ``kappa = norm`` if no larger one does).
    """
    best = design(problem, gain_bound=norm, **kw)
    lo, hi = norm, 4.0 * norm
    top = _try_design(design, problem, hi, kw)
    if top is not None and np.linalg.norm(top.K, 2) <= norm:
        return top
    while hi - lo > rel_tol * hi:
        mid = 0.5 * (lo + hi)
        r = _try_design(design, problem, mid, kw)
        if r is not None and np.linalg.norm(r.K, 2) <= norm:
            lo, best = mid, r
        else:
            hi = mid
    return best


def _try_design(design: Callable[..., DesignResult], problem: Problem, kappa: float,
                kw: dict[str, Any]) -> DesignResult | None:
    try:
        return design(problem, gain_bound=kappa, **kw)
    except LmiError:
        return None
