"""Theorem 1's reduced LMI for n >= 8 (issue 15, item 4): size n + rank(A_tau) + rank(F).

The reduced program must decide feasibility like the paper's form and every gain it returns
must pass the same independent check on the original problem.  No timing here
(``benchmarks/synthesis_scaling.py`` measures the speed)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from conftest import CONFIG
from nonfragile_tracker.control.synthesis import lmi
from nonfragile_tracker.control.synthesis.lmi import synthesize, verify_certificate
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.synthesis.errors import InfeasibleError

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

PAPER = load_problem(CONFIG / 'paper_problem.yaml')


def coupled(k: int, seed: int = 0):
    bd = lambda M: sla.block_diag(*([M] * k))  # noqa: E731
    p = PAPER.replace(A=bd(PAPER.A), B=bd(PAPER.B), A_tau=bd(PAPER.A_tau), E=bd(PAPER.E),
                      F=bd(PAPER.F), perturbations={}, name=f'coupled{4 * k}')
    rng = np.random.default_rng(seed)
    return p.replace(A=p.A + 0.02 * rng.standard_normal((p.n, p.n)))


def random_problem(n: int, m: int, seed: int, ad_rank: int | None = None):
    rng = np.random.default_rng(seed)
    Ad = 0.1 * rng.standard_normal((n, n))
    if ad_rank is not None:
        Ad = 0.1 * rng.standard_normal((n, ad_rank)) @ rng.standard_normal((ad_rank, n))
    return PAPER.replace(A=rng.standard_normal((n, n)) / np.sqrt(n),
                         B=rng.standard_normal((n, m)), A_tau=Ad,
                         E=0.3 * rng.standard_normal((m, 2)),
                         F=0.3 * rng.standard_normal((3, n)), perturbations={},
                         name=f'random{n}')


def test_ranks_of_the_stacked_robots():
    """Each robot's A_tau has rank 2 and its F rank 1: sizes n/2 and n/4."""
    assert lmi._reduced_shape(coupled(3)) == (6, 3)
    assert lmi._reduced_shape(random_problem(9, 3, 0)) == (9, 3)
    assert lmi._reduced_shape(random_problem(9, 3, 0, ad_rank=2)) == (2, 3)
    assert lmi._reduced_shape(random_problem(9, 3, 0).replace(A_tau=np.zeros((9, 9)))) == (0, 3)


@pytest.mark.parametrize('nominal', [False, True])
def test_reduced_and_paper_forms_agree(nominal, monkeypatch):
    """Same verdict and the same capped margin t = 1 under a gain bound, both verified."""
    p = coupled(3)
    red = synthesize(p, nominal=nominal, gain_bound=8.67)
    monkeypatch.setattr(lmi, 'COMPACT_FROM_N', 1000)
    paper = synthesize(p, nominal=nominal, gain_bound=8.67)
    for r in (red, paper):
        assert verify_certificate(p, r.K, r.P, r.Q, r.eps).ok
        assert np.linalg.norm(r.K, 2) <= 8.67 * (1 + 1e-9)
    assert abs(red.margin_achieved - paper.margin_achieved) < 1e-6
    # the reduced program does not impose X >= I: the bound's cone gives X >= I / 2
    assert np.linalg.eigvalsh(red.P)[-1] <= 2.0 * (1 + 1e-6)


@pytest.mark.parametrize('ad_rank', [None, 3, 0])
def test_reduced_form_on_random_data(ad_rank):
    """Full-rank, low-rank and zero A_tau: verified gains, bounded and unbounded."""
    p = random_problem(9, 3, 2, ad_rank=ad_rank)
    if ad_rank == 0:
        p = p.replace(A_tau=np.zeros((9, 9)))
    for kw in (dict(gain_bound=20.0), dict()):
        r = synthesize(p, **kw)
        ver = verify_certificate(p, r.K, r.P, r.Q, r.eps)
        assert ver.ok and ver.max_eig_V < -1e-9 * ver.scale
        assert np.all(np.linalg.eigvalsh(r.Q) > 0)
        if kw:
            assert np.linalg.norm(r.K, 2) <= 20.0 * (1 + 1e-9)


def test_reduced_form_reports_infeasibility():
    """An unreachable extra state z' = -z + 2 z(t - tau) in each of three coupled copies."""
    base = coupled(3)
    n = base.n + 2
    A = np.zeros((n, n)); A[:-2, :-2] = base.A; A[-2, -2] = A[-1, -1] = -1.0
    A[-1, 0] = 0.1
    Ad = np.zeros((n, n)); Ad[:-2, :-2] = base.A_tau; Ad[-2, -2] = Ad[-1, -1] = 2.0
    p = base.replace(A=A, B=np.vstack([base.B, np.zeros((2, base.m))]), A_tau=Ad,
                     F=np.hstack([base.F, np.zeros((base.F.shape[0], 2))]), name='extra')
    with pytest.raises(InfeasibleError, match="infeasible for problem 'extra'"):
        synthesize(p, gain_bound=8.67)


def test_paper_form_is_the_last_resort(monkeypatch):
    """If no point of the reduced program verifies, the paper's form decides."""
    p = coupled(3)
    real = lmi._ReducedProgram.point

    def broken(self, *args, **kw):
        status, t, X, Q, R, eps, st = real(self, *args, **kw)
        return status, t, X, Q, None if R is None else -R, eps, st
    monkeypatch.setattr(lmi._ReducedProgram, 'point', broken)
    res = synthesize(p, gain_bound=8.67, solver='CLARABEL')
    assert res.extra['recovered_by'].startswith('paper-form LMI')
    assert verify_certificate(p, res.K, res.P, res.Q, res.eps).ok
    assert np.linalg.norm(res.K, 2) <= 8.67 * (1 + 1e-9)
