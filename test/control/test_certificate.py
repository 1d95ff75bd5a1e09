"""The certificate base shared by the LMI modules (control/synthesis/certificate.py): one numpy check,
one record shape, one K-shape check; no solver involved (fast)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nonfragile_tracker.control.synthesis.certificate import eigen_figures, passes, signs_hold
from nonfragile_tracker.control.synthesis.delay_dependent import DelayDependentVerification
from nonfragile_tracker.control.synthesis.input_delay import InputDelayVerification
from nonfragile_tracker.control.synthesis.lmi import Verification, verify_certificate
from nonfragile_tracker.control.synthesis.problem import Problem
from nonfragile_tracker.errors import InputError

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical


def scalar_problem() -> Problem:
    """x' = -x + u + 0.1 x(t - tau), one input, E = F = 0.5: small enough to check by hand."""
    one = np.ones((1, 1))
    return Problem(A=-one, B=one, A_tau=0.1 * one, tau=0.1, E=0.5 * one, F=0.5 * one)


def test_eigen_figures_are_the_eigenvalues():
    M = np.diag([-3.0, -1.0])
    top, scale, mins = eigen_figures(M, (np.diag([2.0, 5.0]), np.array([[1.0, 2.0], [0.0, 1.0]])))
    assert (top, scale) == (-1.0, 3.0)
    # the symmetric part of [[1, 2], [0, 1]] is [[1, 1], [1, 1]]: eigenvalues 0 and 2
    assert mins == pytest.approx([2.0, 0.0], abs=1e-15)
    assert passes(top, scale, [2.0], None, 1e-9)
    assert not passes(top, scale, [2.0, 0.0], None, 1e-9)        # P not definite
    assert not passes(top, scale, [2.0], -1.0, 1e-9)             # Petersen scalar <= 0
    assert not passes(-1e-12, 3.0, [2.0], None, 1e-9)            # slack below tol * scale
    assert signs_hold([1.0], 0.5) and not signs_hold([1.0], 0.0)


def test_anything_not_finite_fails():
    M = np.array([[-1.0, math.nan], [math.nan, -1.0]])
    top, scale, mins = eigen_figures(M, (np.eye(2),))
    assert (top, scale, mins) == (math.inf, math.inf, [-math.inf])
    assert not passes(top, scale, mins, None, 1e-9)


def test_reports_print_the_fields_of_each_record():
    v = Verification(True, -0.07912, 0.1848, 0.07957, tolerance=1e-9, scale=2.0)
    # the line of the gain files written by `synthesize` (test/data/golden_gains.yaml)
    assert v.describe() == 'max eig V = -0.07912, min eig P = 0.1848, min eig Q = 0.07957'
    assert v.worst_eigenvalue == -0.07912
    assert v.as_dict() == {'ok': True, 'tolerance': 1e-9, 'scale': 2.0, 'max_eig_V': -0.07912,
                           'min_eig_P': 0.1848, 'min_eig_Q': 0.07957}
    d = DelayDependentVerification(False, -1.0, 1.0, 2.0, 3.0, None, tolerance=1e-9, scale=4.0)
    assert d.describe() == ('max eig Psi = -1, min eig P1 = 1, min eig S = 2, '
                            'min eig R = 3')
    i = InputDelayVerification(True, -2.0, 0.5, 0.25, 1.0, tolerance=1e-9, scale=3.0)
    assert i.worst_eigenvalue == -2.0 and i.congruent is False
    assert 'min eig of the reciprocally convex block = 0.25' in i.describe()


def test_verify_certificate_by_hand_and_the_one_k_shape_check():
    """n = m = q = p = 1: ``V`` is 3 x 3 and its eigenvalues are those numpy gives."""
    p = scalar_problem()
    K, P, Q, eps = np.array([[-1.0]]), np.array([[1.0]]), np.array([[0.5]]), 1.0
    a0 = -2.0                                               # A + B K
    V = np.array([[2 * a0 + 0.5 + 0.25 / eps, 0.1, 0.5],
                  [0.1, -0.5, 0.0],
                  [0.5, 0.0, -1.0 / eps]])
    ev = np.linalg.eigvalsh(V)
    ver = verify_certificate(p, K, P, Q, eps)
    assert ver.ok
    assert ver.max_eig_V == pytest.approx(ev[-1], abs=1e-15)
    assert ver.scale == pytest.approx(np.max(np.abs(ev)), abs=1e-15)
    assert (ver.min_eig_P, ver.min_eig_Q) == (1.0, 0.5)
    assert not verify_certificate(p, K, P, Q, -1.0).ok        # eps <= 0
    with pytest.raises(InputError, match=r'K must have shape \(1, 1\)'):
        verify_certificate(p, np.zeros((1, 2)), P, Q, eps)
