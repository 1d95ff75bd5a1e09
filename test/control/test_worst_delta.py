"""The worst constant Delta of the exact figures (control.synthesis.worst_delta): searched
over the extreme points of the unit ball for Delta's shape and refined, never only
{0, listed, +-I}."""
import math

import numpy as np

from conftest import CONFIG
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.synthesis.latency_design import (exact_abscissa, lagged_problem,
                                                                 perturbation_set)
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.synthesis.worst_delta import extreme_deltas, worst_delta


def test_extreme_points_have_every_singular_value_one():
    for q, r in ((2, 2), (2, 1), (1, 3), (3, 2), (3, 3)):
        for D in extreme_deltas(q, r, samples=8):
            assert D.shape == (q, r)
            np.testing.assert_allclose(np.linalg.svd(D, compute_uv=False), 1.0, atol=1e-12)
    # 2 x 2: rotations and reflections
    dets = {round(float(np.linalg.det(D))) for D in extreme_deltas(2, 2, samples=8)}
    assert dets == {1, -1}


def test_non_square_worst_delta_matches_a_dense_search():
    """E 2x2, F 1x4 (Delta 2x1, the old check tried Delta = 0 only): the search's worst
    abscissa of the shipped gain at 0.15 s is at least a dense polar grid's over the ball."""
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    E, F = np.eye(2), np.array([[0.5, 0.5, 0.5, 0.5]])

    def f(D):
        return exact_abscissa(p.A, p.A_tau, p.tau, p.B @ (K + E @ D @ F), 0.15, N=10)

    found, D = worst_delta(f, 2, 1, extra=[np.zeros((2, 1))])
    assert np.linalg.norm(D, 2) <= 1 + 1e-12
    dense = max(f(rad * np.array([[math.cos(a)], [math.sin(a)]]))
                for rad in np.linspace(0.0, 1.0, 11)
                for a in np.linspace(0.0, 2 * math.pi, 120, endpoint=False))
    assert found >= dense - 1e-9
    assert found > f(np.zeros((2, 1))) + 1e-3           # Delta = 0 alone missed it


def test_the_exact_check_finds_a_rotation_worse_than_plus_minus_identity():
    """The shipped gain's lagged loop at 0.15 s: the searched worst Delta is worse than every
    one of {0, listed, +-I} (it is near a rotation, not a sign matrix)."""
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    lp = lagged_problem(p, 0.05)
    Ka = np.hstack([K, np.zeros((2, 2))])

    def f(D):
        return exact_abscissa(lp.A, lp.A_tau, lp.tau, lp.B @ (Ka + lp.E @ D @ lp.F), 0.15)

    old = perturbation_set(lp)
    new = perturbation_set(lp, Ka, 0.15)
    assert len(new) == len(old) + 2
    assert max(f(D) for D in new) > max(f(D) for D in old) + 1e-3
    assert all(np.linalg.norm(D, 2) <= 1 + 1e-12 for D in new)
