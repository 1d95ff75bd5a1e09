"""control.synthesis.search: the bisection and the eps line search (plain functions, no solver)."""
import math

import numpy as np
import pytest

from nonfragile_tracker.control.synthesis.search import (eps_search, golden_section_max,
                                                         largest_feasible, resolution,
                                                         settle_on_grid)

GRID = [float(e) for e in np.logspace(-3, 2, 21)]


def recorder(f):
    calls = []

    def g(e):
        calls.append(e)
        return f(e)
    return g, calls


def bump(peak: float, width: float = 1.0):
    """Unimodal in log eps, maximum 1 at ``peak``."""
    return lambda e: 1.0 - ((math.log(e) - math.log(peak)) / width) ** 2


def test_full_scan_evaluates_the_grid_in_order_then_refines_around_the_best():
    f, calls = recorder(bump(0.2))
    eps_search(f, GRID, 8)
    assert calls[:21] == GRID and len(calls) == 21 + 8
    refined = calls[21:]
    k = int(np.argmax([bump(0.2)(e) for e in GRID]))
    assert all(GRID[k - 1] <= e <= GRID[k + 1] for e in refined)
    best = max(calls, key=bump(0.2))
    assert abs(math.log(best / 0.2)) < 0.02           # the grid step is 0.58 in log eps


@pytest.mark.parametrize('start', [1e-3, 0.01, 0.2, 3.0, 100.0, 0.0042])
def test_warm_start_finds_the_grid_maximum_of_a_unimodal_function(start):
    full, full_calls = recorder(bump(0.2))
    eps_search(full, GRID, 8)
    warm, warm_calls = recorder(bump(0.2))
    eps_search(warm, GRID, 8, start=start)
    assert warm_calls[0] == start
    on_grid = [e for e in warm_calls if e in GRID]
    assert max(on_grid, key=bump(0.2)) == max(GRID, key=bump(0.2))
    assert warm_calls[-8:] == full_calls[-8:]          # the same refinement
    assert len(warm_calls) < len(full_calls)
    assert len(set(warm_calls)) == len(warm_calls)     # no point solved twice


def test_warm_start_near_the_peak_needs_a_handful_of_points():
    f, calls = recorder(bump(0.2))
    eps_search(f, GRID, 8, start=0.2)
    assert len(calls) == 1 + 3 + 8                     # start, grid point and neighbours, refine


def test_warm_start_scans_the_grid_when_nothing_finite_is_near():
    def f(e):                                          # infeasible (-inf) except near 30
        return 1.0 - abs(math.log(e / 30.0)) if e > 5.0 else -math.inf
    g, calls = recorder(f)
    eps_search(g, GRID, 4, start=1e-3)
    assert set(GRID) <= set(calls)
    assert max(calls, key=f) == pytest.approx(30.0, rel=0.2)


def test_no_refinement_when_every_point_is_infeasible():
    g, calls = recorder(lambda e: -math.inf)
    eps_search(g, GRID, 8, start=0.5)
    assert sorted(set(calls) - {0.5}) == GRID and len(calls) == 22


def test_raising_from_f_stops_the_search():
    class Found(Exception):
        pass

    def f(e):
        if bump(0.2)(e) > 0.9:
            raise Found(e)
        return bump(0.2)(e)
    with pytest.raises(Found) as info:
        eps_search(f, GRID, 8)
    assert bump(0.2)(info.value.args[0]) > 0.9


def test_golden_section_converges_on_a_unimodal_function():
    xs = []
    golden_section_max(lambda u: xs.append(u) or -(u - 0.3) ** 2, -1.0, 2.0, 20)
    assert len(xs) == 20 and min(abs(x - 0.3) for x in xs) < 1e-3


def test_largest_feasible_bisects_to_the_relative_tolerance():
    x, r, n = largest_feasible(lambda v: v if v <= 1.37 else None, 0.0, 0.5, rel_tol=1e-3,
                               lo_result=0.0)
    assert 1.37 * (1 - 2e-3) <= x <= 1.37 and r == x and n > 3
    x, r, _ = largest_feasible(lambda v: v, 0.0, 0.5, hi_limit=8.0, lo_result=0.0)
    assert (x, r) == (8.0, 8.0)


def test_a_value_past_accept_that_did_not_stop_the_search_scans_the_rest():
    """The local maximum is good enough but ``f`` did not stop there (its point failed a
    check): the other grid points are tried, and the one that passes stops the search."""
    class Found(Exception):
        pass

    def f(e):
        if e == GRID[15]:
            raise Found(e)
        return bump(0.2)(e)
    g, calls = recorder(f)
    with pytest.raises(Found):
        eps_search(g, GRID, 8, start=0.2, accept=0.5)
    assert calls[-1] == GRID[15] and GRID[0] in calls
    # below accept: the local search alone
    g, calls = recorder(lambda e: bump(0.2)(e) - 2.0)
    eps_search(g, GRID, 8, start=0.2, accept=0.5)
    assert len(calls) == 1 + 3 + 8


def bracketed_trial(root: float, calls: list, score=lambda x, r: r - x):
    def trial(x):
        calls.append(x)
        s = score(x, root)
        return s, (x if x <= root else None)
    return trial


def test_bracketed_search_closes_a_smooth_score_in_fewer_trials_than_halving():
    from nonfragile_tracker.control.synthesis.search import largest_feasible_bracketed
    calls: list = []
    root, tol = 0.7312, 1e-4
    x, res, n = largest_feasible_bracketed(bracketed_trial(root, calls), 0.0, 2.0, 0.0,
                                           tol=tol, lo_score=root, hi_score=root - 2.0)
    assert x <= root < x + tol and res == x and n == len(calls)
    assert n <= 4 < math.ceil(math.log2(2.0 / tol))          # bisection: 15 trials
    # the result is always a point the trial accepted
    assert all((c <= root) == (c <= x) for c in calls if c <= x)


def test_bracketed_search_without_scores_is_bisection_and_never_worse_than_thrice():
    from nonfragile_tracker.control.synthesis.search import largest_feasible_bracketed
    calls: list = []
    root, tol = 0.3, 1e-3
    x, _, n = largest_feasible_bracketed(
        bracketed_trial(root, calls, score=lambda x, r: math.nan), 0.0, 1.0, 0.0, tol=tol)
    assert x <= root < x + tol and n == math.ceil(math.log2(1.0 / tol))
    # a saturated score (flat beyond the root, as the certification LMI's strictness)
    calls2: list = []
    x2, _, n2 = largest_feasible_bracketed(
        bracketed_trial(root, calls2, score=lambda x, r: max(r - x, -1e-12) if x > r
                        else 1.0), 0.0, 1.0, 0.0, tol=tol, lo_score=1.0, hi_score=-1e-12)
    assert x2 <= root < x2 + tol and n2 <= 3 * math.ceil(math.log2(1.0 / tol))


# ----------------------------------------------------------------------------- settle_on_grid
def test_resolution_is_three_significant_digits():
    assert resolution(0.7166) == pytest.approx(1e-3)
    assert resolution(1.508) == pytest.approx(1e-2)
    assert resolution(0.2208) == pytest.approx(1e-3)
    assert resolution(0.0247) == pytest.approx(1e-4)


@pytest.mark.parametrize('x', [0.7163, 0.7166, 0.71675, 0.7121])
def test_settle_lands_on_the_same_grid_value_wherever_the_search_stopped(x):
    """Boundary 0.7168: searches stopping anywhere below it (by up to 5 steps) record 0.716,
    whose own result is returned."""
    calls = []

    def trial(v):
        calls.append(v)
        return ('at', v) if v <= 0.7168 else None

    v, r, n = settle_on_grid(trial, x, ('at', x), 1e-3)
    assert v == 0.716 and r == ('at', 0.716) and n == len(calls)
    assert 0.717 in calls and all(c <= 0.717 for c in calls)


def test_settle_keeps_the_search_result_where_the_grid_value_fails():
    """Not monotone: 0.716 fails though 0.7166 was certified: the value recorded is still
    0.716 (a certified rate implies every smaller one), with the search's result."""
    v, r, n = settle_on_grid(lambda a: None, 0.7166, 'search', 1e-3)
    assert (v, r, n) == (0.716, 'search', 2)


def test_settle_on_a_grid_value_and_below_the_limit():
    v, r, n = settle_on_grid(lambda a: a, 0.5, 0.5, 0.1, hi_limit=0.8)
    assert v == 0.8 and r == 0.8 and n == 3
    v, r, n = settle_on_grid(lambda a: None, 0.5, 'x', 0.1)
    assert (v, r, n) == (0.5, 'x', 1)
