"""The searches of the syntheses, one place each.

:func:`largest_feasible` is the one bisection for every "largest value that is still
certified" search, :func:`largest_feasible_bracketed` the same once a bracket is known (false
position on the solver's strictness), :func:`golden_section_max` a golden-section
refinement, :func:`eps_search` the line search over the tuning scalar ``eps`` of the
delay-dependent and input-delay LMIs (a log grid or a local climb from a warm start, then
golden section), and :func:`resolution` / :func:`settle_on_grid` the stopping rule that
makes a search's result the same on every machine (the largest certified point of a fixed
grid).

See doc/theory.md, section "Synthesis choices", and doc/across-machines.md.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence, TypeVar, overload

__all__ = ['largest_feasible', 'largest_feasible_bracketed', 'golden_section_max', 'eps_search',
           'resolution', 'settle_on_grid']

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
    bisected until ``hi - lo <= rel_tol * hi``.

    Parameters
    ----------
    trial : callable
        ``trial(x)``: a result if ``x`` is feasible, else ``None``.
    lo : float
        A feasible value.
    hi : float
        The first value tried (doubled while feasible).
    rel_tol : float, optional
        Relative width of the final bracket.
    hi_limit : float, optional
        Largest value tried.
    lo_result : object, optional
        ``trial(lo)``, returned when nothing above ``lo`` is feasible.

    Returns
    -------
    x : float
        The largest feasible value found.
    result : object
        ``trial(x)`` (``lo_result`` for ``x = lo``).
    trials : int
        Number of calls of ``trial``.
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


def largest_feasible_bracketed(trial: Callable[[float], tuple[float, T | None]],
                               lo: float, hi: float, lo_result: T, *, tol: float,
                               lo_score: float = math.nan, hi_score: float = math.nan
                               ) -> tuple[float, T, int]:
    """Largest feasible ``x`` in ``[lo, hi)`` within ``tol``, by safeguarded false position.

    ``lo`` is known feasible (its result ``lo_result``) and ``hi`` known infeasible.
    ``trial(x)`` returns ``(score, result)``: ``result`` is None when ``x`` is infeasible,
    and ``score`` is a continuous measure that crosses 0 at the boundary (the SDP's
    strictness ``t - margin``: >= 0 feasible, < 0 not; ``nan`` when unknown).  The next
    ``x`` is the root of the line through the last two feasible scores (the strictness
    is smooth on the feasible side and often kinked at the boundary, where another
    constraint becomes active; for a convex decreasing score the step lands just short of
    the boundary), else of the secant through the bracket's scores (Illinois variant: the
    score of an end that stays twice is halved), kept at least ``tol / 2`` inside the
    bracket; once the estimate is within ``tol`` of an end the step to ``end +- tol`` is
    taken, so a smooth score closes the bracket in a few trials where halving needs
    ``log2((hi - lo) / tol)``; two steps in a row that do not halve the bracket are
    followed by a bisection (a flat or saturated score, e.g. a strictness pinned at 0 on
    the infeasible side, costs at most three times the halving).  Without usable scores
    this is bisection.  Feasibility is decided by ``result`` only, so the returned ``x``
    is always one ``trial`` accepted.

    Parameters
    ----------
    trial : callable
        ``trial(x) -> (score, result or None)``.
    lo, hi : float
        Known feasible and known infeasible ends.
    lo_result : object
        The result at ``lo``.
    tol : float
        Absolute width of the final bracket.
    lo_score, hi_score : float, optional
        Scores at the ends, if known (``nan``: unknown).

    Returns
    -------
    x : float
        The largest accepted value, ``hi - x <= tol`` for the final bracket.
    result : object
        Its result.
    trials : int
        Number of calls of ``trial``.
    """
    best, trials, side = lo_result, 0, 0
    ls, hs = float(lo_score), float(hi_score)
    feasible = [(lo, ls)] if math.isfinite(ls) else []
    bisect, slow = False, 0
    while hi - lo > tol:
        width = hi - lo
        x = math.nan
        if not bisect and len(feasible) >= 2:
            # extrapolate the last two feasible scores: the strictness is smooth on the
            # feasible side, and often kinked at the boundary (another constraint becomes
            # active), so a secant across the boundary is the worse model
            (x1, s1), (x2, s2) = feasible[-2], feasible[-1]
            if s1 > s2 > 0.0 and x2 > x1:
                x = x2 + s2 * (x2 - x1) / (s1 - s2)
        if math.isnan(x) and not bisect and math.isfinite(ls) and math.isfinite(hs) \
                and ls > 0.0 > hs:
            x = hi - hs * (hi - lo) / (hs - ls)
        if math.isfinite(x):
            if x - lo < tol:
                x = lo + min(tol, 0.5 * width)
            elif hi - x < tol:
                x = hi - min(tol, 0.5 * width)
        else:
            x = 0.5 * (lo + hi)
        x = min(max(x, lo + 0.5 * tol), hi - 0.5 * tol)
        score, r = trial(x)
        trials += 1
        if r is not None:
            lo, best = x, r
            ls = max(float(score), 1e-300) if math.isfinite(score) else math.nan
            if math.isfinite(ls):
                feasible.append((x, ls))
            if side > 0 and math.isfinite(hs):
                hs *= 0.5
            side = 1
        else:
            hi = x
            hs = min(float(score), -1e-300) if math.isfinite(score) else math.nan
            if side < 0 and math.isfinite(ls):
                ls *= 0.5
            side = -1
        # safeguard (as in Brent's method): two steps in a row that did not halve the
        # bracket are followed by a bisection, so a poor score costs at most three times
        # the halving
        slow = 0 if bisect or hi - lo <= 0.5 * width else slow + 1
        bisect = slow >= 2
    return lo, best, trials


def golden_section_max(f: Callable[[float], float], a: float, b: float, steps: int) -> None:
    """Golden-section maximization of ``f`` on ``[a, b]`` with ``steps`` evaluations.

    Nothing is returned: callers record the values (and the points they belong to)
    inside ``f``, and may stop early by raising from it.  ``f`` need not be unimodal;
    then this is a heuristic local refinement.

    Parameters
    ----------
    f : callable
        The function to maximize, ``float -> float``.
    a, b : float
        The interval.
    steps : int
        Number of evaluations of ``f``.
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


def eps_search(f: Callable[[float], float], grid: Sequence[float], refine: int, *,
               start: float | None = None, accept: float = math.inf) -> None:
    """Maximize ``f(eps)`` over the positive log grid ``grid``, then refine.

    Without ``start``: ``f`` at every grid point, in the order given.  With ``start``
    (a warm start, e.g. the ``eps`` that worked at the previous trial of a bisection):
    ``f(start)``, then a climb on the sorted grid from the grid point nearest to
    ``start`` (log distance) towards larger values, until both neighbours of a grid
    point are lower (a local maximum of the grid).  The rest of the grid is scanned as
    without ``start`` if no value found that way is finite, or if one is ``>= accept``
    (``f`` was expected to stop the search there but did not, e.g. the solver's point
    failed an independent check: other ``eps`` may give a good point).  Then ``refine``
    golden-section steps in ``log eps`` between the neighbours of the best grid point.

    Like :func:`golden_section_max`, nothing is returned: ``f`` records its points and
    may stop the search by raising.  The warm start trades the global scan for a local
    one: where ``f`` has several local maxima on the grid it may settle on a lower one
    (a bisection using it then returns a smaller, still verified, value).

    Parameters
    ----------
    f : callable
        ``eps -> strictness`` (``-inf``: no point).
    grid : sequence of float
        Positive grid of ``eps`` values.
    refine : int
        Golden-section steps after the grid (0: none).
    start : float, optional
        Warm start (see above).
    accept : float, optional
        A value at which ``f`` was expected to stop the search (see above).
    """
    values: dict[float, float] = {}

    def at(e: float) -> float:
        if e not in values:
            values[e] = f(e)
        return values[e]

    pts = sorted({float(e) for e in grid})
    if start is None:
        for e in grid:
            at(float(e))
    else:
        at(float(start))
        c = math.log(start)
        i = min(range(len(pts)), key=lambda j: abs(math.log(pts[j]) - c))
        while True:
            here = at(pts[i])
            left = at(pts[i - 1]) if i > 0 else -math.inf
            right = at(pts[i + 1]) if i + 1 < len(pts) else -math.inf
            if max(left, right) <= here:
                break
            i = i - 1 if left > right else i + 1
        best = max(values.values())
        if best == -math.inf or best >= accept:
            for e in pts:
                at(e)
    on_grid = [e for e in pts if e in values]
    k = max(range(len(on_grid)), key=lambda j: values[on_grid[j]])
    if refine > 0 and len(pts) > 1 and values[on_grid[k]] > -math.inf:
        j = pts.index(on_grid[k])
        lo, hi = math.log(pts[max(j - 1, 0)]), math.log(pts[min(j + 1, len(pts) - 1)])
        if hi > lo:
            golden_section_max(lambda u: f(math.exp(u)), lo, hi, refine)


def resolution(x: float, digits: int = 3) -> float:
    """The grid step of ``digits`` significant digits at ``x > 0`` (``0.7166 -> 0.001``).

    Parameters
    ----------
    x : float
        A positive value.
    digits : int, optional
        Significant digits resolved.

    Returns
    -------
    float
        ``10 ** (floor(log10 x) - digits + 1)``.
    """
    return float(10.0 ** (math.floor(math.log10(x)) - digits + 1))


def settle_on_grid(trial: Callable[[float], T | None], x: float, result: T, step: float, *,
                   hi_limit: float = math.inf, max_up: int = 20) -> tuple[float, T, int]:
    """The largest multiple of ``step`` certified, from a search's certified ``x``.

    Why: a search that stops within a tolerance of the boundary (Newton steps, false
    position, bisection) stops at a point that depends on the path, and the path on the
    solver's last digits (OpenBLAS picks its kernels by CPU): two machines returned
    0.7163 and 0.7167 1/s for the same design.  Whether a *fixed* value is certified
    moves with those digits only when the value lies within the boundary's own spread
    (about 1e-4 1/s there, against a grid of 1e-3: the strictness at a fixed rate and
    ``eps`` differed by 2e-5 between kernels).  So the answer is
    taken on a fixed grid: ``g = floor(x / step) * step``, then ``g + step`` is tried
    while it is certified (the search may have stopped more than one step short).  The
    result of ``g`` itself is ``trial(g)`` (the design at the value recorded, which does
    not depend on the path either); where ``g`` fails though ``x >= g`` was certified
    (feasibility is not proven monotone) the result of ``x`` is kept: a certified decay
    rate or latency interval ``x`` implies every smaller one (the claim is monotone).

    Parameters
    ----------
    trial : callable
        ``trial(v)``: a result if ``v`` is certified, else ``None``.
    x : float
        A certified value (the search's answer), ``x >= step``.
    result : object
        Its result.
    step : float
        The grid (e.g. :func:`resolution`).
    hi_limit : float, optional
        Largest value tried.
    max_up : int, optional
        Most steps up (a guard: the search's answer is within a step or two).

    Returns
    -------
    value : float
        The multiple of ``step`` (rounded to 12 significant digits).
    result : object
        Its result (see above).
    trials : int
        Number of calls of ``trial``.
    """
    def on_grid(k: int) -> float:
        return float(f'{k * step:.12g}')

    k = math.floor(x / step * (1.0 + 1e-12))
    trials = 0
    up: T | None = None
    for _ in range(max_up):
        v = on_grid(k + 1)
        if v > hi_limit:
            break
        r = trial(v)
        trials += 1
        if r is None:
            break
        k, up = k + 1, r
    if up is not None:
        return on_grid(k), up, trials
    g = on_grid(k)
    if g == x:
        return g, result, trials
    r = trial(g)
    trials += 1
    return g, (result if r is None else r), trials
