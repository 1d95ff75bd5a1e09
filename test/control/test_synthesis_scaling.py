"""Faster synthesis by structure (issue 15, item 4): Theorem 1 on data that decouple into
independent blocks is solved block by block and certified on the whole problem.

No timing here: ``benchmarks/synthesis_scaling.py`` measures the speed."""
from __future__ import annotations


import numpy as np
import pytest
import scipy.linalg as sla

from conftest import CONFIG
from nonfragile_tracker.control.synthesis.delay import closed_loop_matrix, spectral_abscissa
from nonfragile_tracker.control.synthesis.lmi import (decoupled_blocks, synthesize,
                                                      verify_certificate)
from nonfragile_tracker.control.synthesis.problem import load_problem

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

PAPER = load_problem(CONFIG / 'paper_problem.yaml')


def stacked(k: int, perm: np.ndarray | None = None):
    bd = lambda M: sla.block_diag(*([M] * k))  # noqa: E731
    p = PAPER.replace(A=bd(PAPER.A), B=bd(PAPER.B), A_tau=bd(PAPER.A_tau), E=bd(PAPER.E),
                      F=bd(PAPER.F), perturbations={}, name=f'paper_x{k}')
    if perm is None:
        return p
    S = np.eye(p.n)[perm]                 # xi_new = S xi: a relabelling of the states
    return p.replace(A=S @ p.A @ S.T, B=S @ p.B, A_tau=S @ p.A_tau @ S.T, F=p.F @ S.T)


def test_blocks_found_also_when_the_states_are_shuffled():
    assert decoupled_blocks(PAPER) == []
    perm = np.random.default_rng(3).permutation(12)
    blocks = decoupled_blocks(stacked(3, perm))
    assert sorted(b[0].size for b in blocks) == [4, 4, 4]
    assert sorted(np.concatenate([b[0] for b in blocks]).tolist()) == list(range(12))
    # a component without inputs or perturbation: no decoupling
    p = stacked(2)
    assert decoupled_blocks(p.replace(B=p.B[:, :2], E=p.E[:2, :2])) == []


def test_block_synthesis_is_certified_on_the_whole_problem():
    perm = np.random.default_rng(5).permutation(12)
    p = stacked(3, perm)
    res = synthesize(p, gain_bound=8.67)
    assert res.extra['blocks'] == [4, 4, 4]
    ver = verify_certificate(p, res.K, res.P, res.Q, res.eps)
    assert ver.ok and res.certificate.verification.ok
    assert np.linalg.norm(res.K, 2) <= 8.67 * (1 + 1e-9)
    # the gain only feeds back each robot's own states
    for st, inp, _, _ in decoupled_blocks(p):
        other = np.setdiff1d(np.arange(12), st)
        assert np.all(res.K[np.ix_(inp, other)] == 0.0)
    # and the delay loop is stable for Delta = 0, +-I
    for D in (np.zeros((6, 6)), np.eye(6), -np.eye(6)):
        A0 = closed_loop_matrix(p.A, p.B, res.K, p.E, p.F, D)
        assert spectral_abscissa(A0, p.A_tau, p.tau) < -0.05


def test_block_and_whole_solves_agree_on_feasibility():
    p = stacked(2)
    whole = synthesize(p, gain_bound=8.67, decouple=False)
    blocks = synthesize(p, gain_bound=8.67)
    assert 'blocks' not in whole.extra and blocks.extra['blocks'] == [4, 4]
    for r in (whole, blocks):
        assert verify_certificate(p, r.K, r.P, r.Q, r.eps).ok
    # the nominal design decouples too
    nom = synthesize(p, nominal=True, gain_bound=8.67)
    assert nom.eps is None and nom.extra['blocks'] == [4, 4]
    assert verify_certificate(p, nom.K, nom.P, nom.Q, None).ok


def coupled(k: int, seed: int = 0):
    p = stacked(k)
    rng = np.random.default_rng(seed)
    return p.replace(A=p.A + 0.02 * rng.standard_normal((p.n, p.n)), name=f'coupled{p.n}')


def test_compact_form_matches_the_paper_form(monkeypatch):
    """n >= 8 uses the reduced LMI (size n + rank A_tau + rank F): same verdict, verified."""
    import nonfragile_tracker.control.synthesis.lmi as lmi
    p = coupled(2)
    assert decoupled_blocks(p) == [] and p.n >= lmi.COMPACT_FROM_N
    for nominal in (False, True):
        compact = synthesize(p, nominal=nominal, gain_bound=8.67)
        assert verify_certificate(p, compact.K, compact.P, compact.Q, compact.eps).ok
        assert np.linalg.norm(compact.K, 2) <= 8.67 * (1 + 1e-9)
        free = synthesize(p, nominal=nominal)
        assert verify_certificate(p, free.K, free.P, free.Q, free.eps).ok
    monkeypatch.setattr(lmi, 'COMPACT_FROM_N', 1000)
    paper = synthesize(p, gain_bound=8.67)
    assert verify_certificate(p, paper.K, paper.P, paper.Q, paper.eps).ok
    # both forms reach the cap t = 1 of the gain-bounded program here
    assert abs(paper.margin_achieved - compact.margin_achieved) < 1e-6


def test_compact_form_reports_infeasibility():
    """An unreachable extra state z' = -z + 2 z(t - tau) in each of two coupled copies."""
    import pytest
    from nonfragile_tracker.control.synthesis.errors import InfeasibleError
    base = coupled(2)
    n = base.n + 2
    A = np.zeros((n, n)); A[:-2, :-2] = base.A; A[-2, -2] = A[-1, -1] = -1.0
    A[-1, 0] = 0.1                                     # couple the extra states in
    Ad = np.zeros((n, n)); Ad[:-2, :-2] = base.A_tau; Ad[-2, -2] = Ad[-1, -1] = 2.0
    p = base.replace(A=A, B=np.vstack([base.B, np.zeros((2, base.m))]), A_tau=Ad,
                     F=np.hstack([base.F, np.zeros((base.F.shape[0], 2))]), name='extra')
    with pytest.raises(InfeasibleError, match="infeasible for problem 'extra'"):
        synthesize(p)
