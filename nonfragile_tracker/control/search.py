"""One bisection for every "largest value that is still certified/feasible" search."""
from __future__ import annotations

import math
from typing import Callable, TypeVar, overload

__all__ = ['largest_feasible', 'golden_section_max']

T = TypeVar('T')


@overload
def largest_feasible(trial: Callable[[float], T | None], lo: float, hi: float, *,
                     rel_tol: float = ..., hi_limit: float = ..., lo_result: T
                     ) -> tuple[float, T, int]: ...
@overload
def largest_feasible(trial: Callable[[float], T | None], lo: float, hi: float, *,
                     rel_tol: float = ..., hi_limit: float = ..., lo_result: None = None
                     ) -> tuple[float, T | None, int]: ...
def largest_feasible(trial: Callable[[float], T | None], lo: float, hi: float, *,
                     rel_tol: float = 1e-3, hi_limit: float = 1e6,
                     lo_result: T | None = None) -> tuple[float, T | None, int]:
    """Largest ``x`` in ``[lo, hi_limit]`` with ``trial(x)`` not None, by doubling then bisection.

    ``trial`` must be monotone (feasible at ``x`` implies feasible below ``x``) and
    ``lo`` known feasible (its result ``lo_result``).  ``hi`` doubles while feasible,
    up to ``hi_limit`` (returned as is if feasible there), then the bracket is
    bisected until ``hi - lo <= rel_tol * hi``.  Returns ``(x, trial(x), trials)``.
    """
    best, trials = lo_result, 0
    while True:
        r = trial(hi)
        trials += 1
        if r is None:
            break
        lo, best = hi, r
        if hi >= hi_limit:
            return lo, best, trials
        hi = min(2.0 * hi, hi_limit)
    while hi - lo > rel_tol * max(abs(hi), 1e-12):
        mid = 0.5 * (lo + hi)
        r = trial(mid)
        trials += 1
        if r is None:
            hi = mid
        else:
            lo, best = mid, r
    return lo, best, trials


def golden_section_max(f: Callable[[float], float], a: float, b: float, steps: int) -> None:
    """Golden-section maximization of ``f`` on ``[a, b]`` with ``steps`` evaluations.

    Nothing is returned: callers record the values (and the points they belong to)
    inside ``f``, and may stop early by raising from it.  ``f`` need not be unimodal;
    then this is a heuristic local refinement.
    """
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(max(0, steps - 2)):
        if fc >= fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = f(d)
