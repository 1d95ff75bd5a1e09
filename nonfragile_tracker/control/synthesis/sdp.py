"""Shared SDP plumbing for the LMI syntheses (Theorem 1, delay-dependent, input delay).

The symmetric part (:func:`sym`), the solver defaults and accepted statuses, one solve that
maps solver exceptions (:func:`solve`), one verdict on a solved point (:func:`classify`),
and ONE bounded, per-thread cache of parametrized cvxpy programs (:func:`cached_program`,
:func:`clear_cache`, :func:`cached_programs`).  No ROS import; cvxpy is imported lazily by
the programs themselves.

See doc/developing.md, section "SDP plumbing".
"""
from __future__ import annotations

import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable, Hashable, TypeVar, cast

import numpy as np

from ...errors import InputError
from .errors import SolverFailure

__all__ = ['DEFAULT_MARGIN', 'DEFAULT_SOLVER', 'OK_STATUSES', 'INFEASIBLE_STATUSES',
           'CACHE_SIZE', 'SolveOutcome', 'sym', 'solve', 'classify', 'cached_program',
           'cached_programs', 'clear_cache']

#: Required strictness ``t`` (normalized units) unless a problem or caller says otherwise.
DEFAULT_MARGIN = 1e-6
#: cvxpy solver used unless a problem or caller says otherwise.
DEFAULT_SOLVER = 'CLARABEL'
#: Statuses whose point is read (and then verified independently).
OK_STATUSES: tuple[str, ...] = ('optimal', 'optimal_inaccurate')
#: Statuses that prove (up to the solver's accuracy) that no point exists.
INFEASIBLE_STATUSES: tuple[str, ...] = ('infeasible', 'infeasible_inaccurate')
#: Largest number of programs kept by the shared cache (least recently used dropped first).
CACHE_SIZE = 32

T = TypeVar('T')


def sym(M: np.ndarray) -> np.ndarray:
    """Symmetric part ``(M + M^T) / 2`` of a square array.

    Parameters
    ----------
    M : array_like, shape (n, n)

    Returns
    -------
    numpy.ndarray, shape (n, n)
    """
    M = np.asarray(M, float)
    return cast(np.ndarray, 0.5 * (M + M.T))


@dataclass(frozen=True)
class SolveOutcome:
    """Status of one solve and the seconds spent inside the solver."""

    status: str
    solve_time: float


def solve(problem: Any, solver: str, *, what: str = 'the LMI',
          quiet_inaccurate: bool = False, ignore_dpp: bool = False) -> SolveOutcome:
    """Solve the cvxpy ``problem`` with ``solver``.

    Parameters
    ----------
    problem : cvxpy.Problem
        The (possibly cached, re-parametrized) problem.
    solver : str
        cvxpy solver name.
    what : str, optional
        Description used in the error message.
    quiet_inaccurate : bool, optional
        Suppress cvxpy's "Solution may be inaccurate" warning (the status says it and
        the point is verified independently anyway).
    ignore_dpp : bool, optional
        Compile with the parameters' current values as constants: several times faster
        than cvxpy's parametrized (DPP) compilation, but nothing is kept for a re-solve.
        Worth it for the first solve of a cached program (most are solved only once).

    Returns
    -------
    SolveOutcome

    Raises
    ------
    SolverFailure
        The solver raised (missing, crashed).
    """
    import cvxpy as cp
    try:
        with warnings.catch_warnings():
            if quiet_inaccurate:
                warnings.filterwarnings('ignore', message='Solution may be inaccurate')
            problem.solve(solver=solver, ignore_dpp=ignore_dpp)
    except cp.error.SolverError as exc:
        raise SolverFailure(f'solver {solver} failed on {what}: {exc}. Check that the solver '
                            'is installed (pip install clarabel).') from None
    stats = problem.solver_stats
    st = float(stats.solve_time or 0.0) if stats is not None else 0.0
    return SolveOutcome(status=str(problem.status), solve_time=st)


def solve_for_point(problem: Any, solver: str, what: str, t: Any, X: Any
                    ) -> tuple[SolveOutcome, float | None, bool]:
    """Solve a strictness-maximizing LMI program and say whether its point is usable.

    The searches over a tuning scalar (delay-dependent and input-delay designs) solve
    many points: a solver failure at one of them is a status, not an exception.

    Parameters
    ----------
    problem : cvxpy.Problem
        The program (cvxpy's "inaccurate" warning is suppressed: the point is verified).
    solver : str
        cvxpy solver name.
    what : str
        Description used in the status of a failure.
    t : cvxpy.Variable
        The strictness variable.
    X : cvxpy.Variable
        A variable that has a value iff the solver returned a point.

    Returns
    -------
    outcome : SolveOutcome
        Status ``'solver_error: ...'`` and 0 s when the solver raised.
    t : float or None
        The value of ``t`` (``None``: none).
    usable : bool
        The status is in :data:`OK_STATUSES` and the point has values.
    """
    try:
        out = solve(problem, solver, what=what, quiet_inaccurate=True)
    except SolverFailure as exc:
        return SolveOutcome(f'solver_error: {exc}', 0.0), None, False
    tv = t.value
    return (out, None if tv is None else float(tv),
            out.status in OK_STATUSES and X.value is not None)


class DescriptorParameters:
    """The data of the descriptor-method programs (delay-dependent and input-delay designs).

    A subclass creates the cvxpy parameters ``A``, ``B``, ``Ad`` (the problem's ``A``,
    ``B``, ``A_tau``), ``eA``, ``eB``, ``eAd`` (the same times the tuning scalar ``eps``,
    so that the products stay DPP), ``eps``, and unless ``nominal`` ``BE``, ``eBE``
    (``B E``, ``eps B E``) and ``F``; :meth:`gain_bound_constraints` adds ``kappa2``.
    """

    nominal: bool
    A: Any
    B: Any
    Ad: Any
    eA: Any
    eB: Any
    eAd: Any
    eps: Any
    BE: Any
    eBE: Any
    F: Any
    kappa2: Any = None

    def set_problem(self, problem: Any, kappa: float | None) -> None:
        """Put ``problem``'s matrices (and the gain bound ``kappa``) into the parameters.

        Parameters
        ----------
        problem : Problem
            The data ``A, B, A_tau, E, F``.
        kappa : float or None
            The ``||K||_2`` bound; required iff the program has one.
        """
        self.A.value, self.B.value, self.Ad.value = problem.A, problem.B, problem.A_tau
        if not self.nominal:
            self.BE.value = problem.B @ problem.E
            self.F.value = problem.F
        if self.kappa2 is not None:
            if kappa is None:
                raise InputError('this program has a gain bound: kappa is required')
            self.kappa2.value = float(kappa) ** 2

    def set_eps(self, problem: Any, eps: float) -> None:
        """Put the tuning scalar ``eps`` (``P3 = eps P2``) and the scaled data in.

        Parameters
        ----------
        problem : Problem
            The data (as given to :meth:`set_problem`).
        eps : float
            The tuning scalar (> 0).
        """
        self.eps.value = eps
        self.eA.value, self.eB.value = eps * problem.A, eps * problem.B
        self.eAd.value = eps * problem.A_tau
        if not self.nominal:
            self.eBE.value = eps * (problem.B @ problem.E)

    def gain_bound_constraints(self, X: Any, Y: Any, t: Any) -> list[Any]:
        """``||K||_2 <= kappa`` for ``K = Y X^-1`` with a non-symmetric ``X`` (creates ``kappa2``).

        ``He(X) / 2 >= I`` and ``[[kappa^2 (He(X) - I), Y^T], [Y, I]] >= 0`` (doc/theory.md,
        "Delay-dependent design"), and ``t <= 1`` fixes the scale in place of a trace bound.

        Parameters
        ----------
        X : cvxpy.Variable, shape (n, n)
            The congruence variable (``X = P2^-1``).
        Y : cvxpy.Variable, shape (m, n)
            ``Y = K X``.
        t : cvxpy.Variable
            The strictness.

        Returns
        -------
        list
            The three constraints.
        """
        import cvxpy as cp
        n, m = X.shape[0], Y.shape[0]
        In = np.eye(n)
        self.kappa2 = cp.Parameter(nonneg=True)
        He = X + X.T
        Gk = cp.bmat([[self.kappa2 * (He - In), Y.T], [Y, np.eye(m)]])
        return [0.5 * He >> In, 0.5 * (Gk + Gk.T) >> 0, t <= 1]


def classify(status: str, t: float | None, margin: float) -> str:
    """``'ok'`` (usable point with ``t >= margin``), ``'infeasible'`` or ``'failed'``.

    A solved problem whose best strictness is below ``margin`` counts as infeasible
    (no point with the required margin exists), as do the infeasible statuses; any
    other status (unbounded, solver error, no value) is a failure.

    Parameters
    ----------
    status : str
        The cvxpy status of the solve.
    t : float or None
        The strictness reached (``None``: the solver gave no value).
    margin : float
        The strictness required.

    Returns
    -------
    str
    """
    if status in INFEASIBLE_STATUSES:
        return 'infeasible'
    if status in OK_STATUSES:
        if t is None:
            return 'infeasible'
        return 'ok' if t >= margin else 'infeasible'
    return 'failed'


class _LruCache:
    def __init__(self, size: int) -> None:
        self.size = size
        self.items: OrderedDict[Hashable, Any] = OrderedDict()

    def get(self, key: Hashable, factory: Callable[[], T]) -> T:
        if key in self.items:
            self.items.move_to_end(key)
            return cast(T, self.items[key])
        value = factory()
        self.items[key] = value
        while len(self.items) > self.size:
            self.items.popitem(last=False)
        return value


class _PerThread(threading.local):
    def __init__(self) -> None:
        self.cache = _LruCache(CACHE_SIZE)


_LOCAL = _PerThread()


def cached_program(key: Hashable, factory: Callable[[], T]) -> T:
    """The program cached under ``key``, built with ``factory()`` on a miss.

    ``key`` must name the module and everything that changes the program's structure
    (shapes, options), e.g. ``('theorem1', n, m, q, p, nominal, gain_bound)``.

    Parameters
    ----------
    key : hashable
        The cache key.
    factory : callable
        Builds the program (no arguments).

    Returns
    -------
    object
        The cached or new program (the most recently used of the cache).
    """
    return _LOCAL.cache.get(key, factory)


def cached_programs() -> list[tuple[Hashable, Any]]:
    """``(key, program)`` pairs in the cache, least recently used first (diagnostics)."""
    return list(_LOCAL.cache.items.items())


def clear_cache() -> None:
    """Drop every cached program (the next synthesis builds and compiles again)."""
    _LOCAL.cache.items.clear()
