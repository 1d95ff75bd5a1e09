"""The dual-based slopes that steer the latency design's searches (issue 24) against finite
differences of the solved objective.

``latency-design`` brackets its searches with Newton steps whose slopes are read from the dual
of the solve just made (envelope theorem): ``d t / d h_max`` of the fixed-gain certification
LMI (:attr:`InputDelayCertification.slope`, used by ``certified_input_delay_of_gain``) and
``d t / d alpha`` of the synthesis LMI at a fixed ``eps`` (``input_delay._alpha_slope``, used
by ``max_input_delay_decay_rate``).  Here each is compared with the slope of a cubic fitted
by least squares to the solved strictness ``t`` at five points around the same place (a fit
rather than one difference quotient: it averages the solver's noise in ``t``, and its
residual measures that noise, asserted small so that a noisy solve cannot pass unnoticed).

Paper problem (n = 4, state delay included), the shipped gain for the certification LMI and
``||K|| <= 8.67``, ``eps = 0.32`` (the search's usual ``eps``) for the synthesis LMI; about
5 s.  Measured (CLARABEL): ``d t/d h_max`` at 0.1 s -9.21318e-3 by the dual, -9.21317e-3 by
the fit (residual 3e-10); ``d t/d alpha`` at 1 1/s -2.1904 by the dual, -2.1849 by the fit
(residual 2.7e-5; t = 0.37).
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT
from nonfragile_tracker.control.synthesis import input_delay
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.synthesis.input_delay import certify_input_delay

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

#: offsets of the fitted points (in units of the step) and the cubic fitted through them
OFFSETS = np.arange(-2, 3)


def fitted_slope(f, x0: float, step: float) -> tuple[float, float]:
    """Slope at ``x0`` of a least-squares cubic through ``f`` at ``x0 + OFFSETS * step``, and
    the largest residual of the fit (the noise of ``f``)."""
    xs = OFFSETS * step
    ys = np.array([f(x0 + x) for x in xs])
    coef = np.polyfit(xs, ys, 3)
    return float(coef[-2]), float(np.max(np.abs(ys - np.polyval(coef, xs))))


def test_certification_slope_in_h_max_is_the_derivative_of_t(paper_problem):
    """``d t / d h_max`` of the certification LMI at ``[0, 0.1]`` s, shipped gain.

    ``t(h_max)`` is smooth here (the fit's residual is 3e-10 against ``t`` = 3e-3), so the
    fitted slope is known to about 1e-7, 1e-5 of its value; the dual agrees to 1e-6.  The
    tolerance 1e-3 leaves the solver's accuracy on another machine two orders of magnitude.
    """
    K = read_gain_file(ROOT / 'config' / 'tracker_gains.yaml')
    at = certify_input_delay(paper_problem, K, 0.0, 0.1)
    assert at.certified and at.slope < 0
    fit, noise = fitted_slope(
        lambda h: certify_input_delay(paper_problem, K, 0.0, h).margin_achieved, 0.1, 1e-3)
    assert noise < 1e-8
    assert at.slope == pytest.approx(fit, rel=1e-3)


def test_synthesis_slope_in_alpha_is_the_derivative_of_t(paper_problem):
    """``d t / d alpha`` of the synthesis LMI at ``eps = 0.32``, ``[0, 0.1]`` s, ``alpha = 1``.

    The synthesis program's ``t`` carries a solver noise of about 3e-5 (the fit's
    residual), so the points are 1e-2 apart: the fitted slope is then known to about
    4e-4 (noise over the spread of the points) and the cubic's truncation is below that.
    The dual slope differs from it by 0.25 % (the accuracy of the solver's dual at its
    default tolerances); it only sizes a Newton step, each of which is verified, so the
    tolerance is 1 % (four times what is measured) - a slope of the wrong weights or sign
    would be off by tens of per cent.
    """
    p = paper_problem
    prog = input_delay._program(p, False, True, True)
    prog.set_data(p, 8.67)

    def t_at(alpha: float) -> float:
        return float(prog.solve(p, 0.0, 0.1, alpha, 0.32, 'CLARABEL').t)

    fit, noise = fitted_slope(t_at, 1.0, 1e-2)
    assert noise < 2e-4
    t = t_at(1.0)                       # the program's last solve: its duals are read below
    assert 0.1 < t < 1.0                # strictly inside: not capped by t <= 1
    slope = input_delay._alpha_slope(prog, 0.0, 0.1, 1.0, p.tau)
    assert slope < 0
    assert slope == pytest.approx(fit, rel=1e-2)
