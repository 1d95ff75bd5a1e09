"""Unicycle model and its exact linearization (paper eq. 2-4)."""
import math

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.model import (InputError,
                                                         double_integrator_model, inputs_from_u,
                                                         u_from_inputs, xi_from_state)


def test_matrices_of_eq4():
    mdl = double_integrator_model()
    np.testing.assert_array_equal(mdl.A, [[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]])
    np.testing.assert_array_equal(mdl.B, [[0, 0], [1, 0], [0, 0], [0, 1]])
    np.testing.assert_array_equal(mdl.C, [[1, 0, 0, 0], [0, 0, 1, 0]])
    assert (mdl.n, mdl.m) == (4, 2)
    assert double_integrator_model(3).A.shape == (6, 6)


def test_xi_and_round_trip_of_inputs():
    rng = np.random.default_rng(1)
    for _ in range(200):
        th, v = rng.uniform(-math.pi, math.pi), rng.uniform(0.05, 2) * rng.choice([-1, 1])
        a, w = rng.normal(size=2)
        u = u_from_inputs(th, v, a, w)
        a2, w2 = inputs_from_u(th, v, *u)
        assert a2 == pytest.approx(a, abs=1e-12) and w2 == pytest.approx(w, abs=1e-12)
    assert xi_from_state(1.0, 2.0, math.pi / 2, 3.0) == pytest.approx((1.0, 0.0, 2.0, 3.0))


def test_linearization_is_exact_along_a_trajectory():
    """d/dt xi equals [xi2, u1, xi4, u2] for the unicycle with v' = a (finite differences)."""
    x, y, th, v, a, w, h = 0.3, -0.2, 0.4, 0.7, 0.5, -0.8, 1e-6

    def f(s):
        return np.array([s[3] * math.cos(s[2]), s[3] * math.sin(s[2]), w, a])
    s = np.array([x, y, th, v])
    s2 = s + h * f(s + 0.5 * h * f(s))
    xi1, xi2 = np.array(xi_from_state(*s)), np.array(xi_from_state(*s2))
    u = u_from_inputs(th, v, a, w)
    np.testing.assert_allclose((xi2 - xi1) / h, [xi1[1], u[0], xi1[3], u[1]], atol=1e-5)


def test_singularity_is_reported():
    with pytest.raises(InputError, match='determinant v'):
        inputs_from_u(0.0, 0.0, 1.0, 1.0)
    with pytest.raises(InputError, match='0.0005'):
        inputs_from_u(0.0, 5e-4, 1.0, 1.0, min_speed=1e-3)
