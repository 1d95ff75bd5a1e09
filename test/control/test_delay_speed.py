"""Delay analysis at every size (issue 15, item 3): accuracy against an independent
refined reference, the problem-dependent discretization degree, and reuse across calls.

No timing here: the speed comparison with tdcpy is ``benchmarks/delay_analysis.py``.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
import yaml
from scipy.sparse.linalg import eigs

from conftest import CONFIG
from nonfragile_tracker.control.synthesis.delay import (closed_loop_matrix, rightmost_roots,
                                                        spectral_abscissa)
from nonfragile_tracker.control.synthesis.problem import load_problem

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical



def _cheb(N: int) -> np.ndarray:
    x = np.cos(np.pi * np.arange(N + 1) / N)
    c = np.hstack([2.0, np.ones(N - 1), 2.0]) * (-1.0) ** np.arange(N + 1)
    dx = x[:, None] - x[None, :]
    D = np.outer(c, 1.0 / c) / (dx + np.eye(N + 1))
    return D - np.diag(D.sum(axis=1))


def reference_roots(A0, A1, tau: float, keep: int = 8) -> list[complex]:
    """Independent of the module: sparse generator at a high degree, scipy's own sparse
    shift-invert (splu) for the eigenvalues nearest 0 (dense eig when small), then Newton
    on det T(s) with step 1 / tr(T^-1 T') to |step| <= 1e-15 |s|."""
    n = A0.shape[0]
    R = np.linalg.norm(A0, 2) + np.linalg.norm(A1, 2)
    N = int(min(max(48, 3 * R * tau), 160))
    M = sp.kron(sp.csr_matrix(_cheb(N) * (2.0 / tau)), sp.identity(n), format='lil')
    M[:n, :] = 0.0
    M[:n, :n] = A0
    M[:n, N * n:] = A1
    M = M.tocsc()
    if M.shape[0] > 400:
        ev = eigs(M, k=min(M.shape[0] - 2, 3 * n + 40), sigma=0.0, return_eigenvectors=False)
    else:
        ev = np.linalg.eigvals(M.toarray())
    ev = ev[np.abs(ev) < 0.5 * N / tau]
    ev = ev[np.argsort(-ev.real)][:2 * keep]
    I = np.eye(n)
    out: list[complex] = []
    for s in ev:
        s = complex(s)
        for _ in range(100):
            E = np.exp(-s * tau)
            try:
                step = 1.0 / np.trace(np.linalg.solve(s * I - A0 - A1 * E, I + tau * E * A1))
            except np.linalg.LinAlgError:       # landed exactly on the root
                break
            s -= step
            if abs(step) <= 1e-15 * max(1.0, abs(s)):
                break
        if not any(abs(s - u) < 1e-9 * max(1.0, abs(s)) for u in out):
            out.append(s)
    out.sort(key=lambda z: (-z.real, -z.imag))
    return out[:keep]


def random_stable(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return (rng.standard_normal((n, n)) / math.sqrt(n) - 1.5 * np.eye(n),
            0.5 * rng.standard_normal((n, n)) / math.sqrt(n))


def paper_loops() -> dict:
    p = load_problem(CONFIG / 'paper_problem.yaml')
    K = np.array(yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())['K_nf'], float)
    q, r = p.E.shape[1], p.F.shape[0]
    return {f'paper {name}': (closed_loop_matrix(p.A, p.B, K, p.E, p.F, D), p.A_tau, p.tau)
            for name, D in (('0', np.zeros((q, r))), ('-I', -np.eye(q, r)),
                            ('+I', np.eye(q, r)))}


CASES = {**paper_loops(),
         'random n=10 tau=1': random_stable(10, 1) + (1.0,),
         'random n=32 tau=1': random_stable(32, 2) + (1.0,),
         'two states tau=5': (np.array([[0.0, 1.0], [-1.0, -0.5]]),
                              np.array([[0.0, 0.0], [-0.1, -0.1]]), 5.0)}


def stiff_loop() -> tuple[np.ndarray, np.ndarray]:
    """n = 6 with fast stable modes (-40 .. -200, ||A0|| ~ 1e3, as high-gain loops have)
    and a slow oscillatory pair: tau ||A0|| in the hundreds, rightmost roots slow."""
    rng = np.random.default_rng(4)
    S = np.eye(6) + 0.3 * rng.standard_normal((6, 6))
    J = np.zeros((6, 6))
    J[:2, :2] = [[-0.4, 2.0], [-2.0, -0.4]]
    J[2:, 2:] = np.diag([-40.0, -80.0, -120.0, -200.0])
    return S @ J @ np.linalg.inv(S), 0.3 * rng.standard_normal((6, 6))


CASES['stiff n=6 tau=1'] = stiff_loop() + (1.0,)


@pytest.mark.parametrize('name', list(CASES))
def test_abscissa_and_rightmost_roots_match_refined_reference(name):
    A0, A1, tau = CASES[name]
    ref = reference_roots(A0, A1, tau)
    got = rightmost_roots(A0, A1, tau, count=4)
    assert got.converged
    assert abs(got.abscissa - ref[0].real) <= 1e-10
    assert abs(spectral_abscissa(A0, A1, tau) - ref[0].real) <= 1e-10
    # every returned root is a reference root, and no reference root right of the last
    # returned one is missing
    for z in got.roots:
        assert min(abs(complex(z) - s) for s in ref) <= 1e-9 * max(1.0, abs(z))
    for s in ref:
        if s.real >= got.roots[-1].real + 1e-9:
            assert min(abs(complex(z) - s) for z in got.roots) <= 1e-9 * max(1.0, abs(s))


def test_degree_follows_the_delay():
    A0 = np.array([[0.0, 1.0], [-1.0, -0.5]])
    A1 = np.array([[0.0, 0.0], [-0.1, -0.1]])
    Ns = [rightmost_roots(A0, A1, tau, count=2).N for tau in (0.05, 1.0, 5.0, 20.0)]
    assert Ns[0] == 16                       # the smallest degree for a short delay
    assert Ns == sorted(Ns) and Ns[-1] > 2 * Ns[0]
    A0, A1 = random_stable(10, 1)
    n_short = rightmost_roots(A0, A1, 0.05, count=2).N
    n_long = rightmost_roots(A0, A1, 4.0, count=2).N
    assert n_short == 16 and n_long > n_short


def test_reuse_across_calls_does_not_leak_between_problems():
    """The remembered degree / Arnoldi size of one problem is only a start for the next
    of the same shape: alternating two different loops gives each its own roots."""
    A0a, A1a = random_stable(10, 1)
    A0b, A1b = random_stable(10, 7)
    A1b = 3.0 * A1b                         # stronger delay term: different roots, larger R
    ref_a = reference_roots(A0a, A1a, 1.0)[0].real
    ref_b = reference_roots(A0b, A1b, 1.0)[0].real
    assert abs(ref_a - ref_b) > 1e-3
    for _ in range(2):
        assert abs(spectral_abscissa(A0a, A1a, 1.0) - ref_a) <= 1e-10
        assert abs(spectral_abscissa(A0b, A1b, 1.0) - ref_b) <= 1e-10
