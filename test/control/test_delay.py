"""Tests of nonfragile_tracker.control.synthesis.delay (characteristic roots, margins).

Reference values come from closed forms (eig, Lambert W, x' = -b x(t - tau),
scalar fragility) or from checks that do not use the module's discretization:
the argument principle on det T(s), a dense scan over ||Delta|| <= 1 and the
real stability radius formula of Qiu et al. (Automatica 1995).
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar
from scipy.special import lambertw

from nonfragile_tracker.control.synthesis.delay import (FragilityResult, RootsResult,
                                                        closed_loop_matrix, delay_margin,
                                                        fragility_margin, is_stable,
                                                        rightmost_roots, spectral_abscissa,
                                                        worst_case_abscissa)

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical

# ----------------------------------------------------------------------------- paper data
A = np.array([[0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]], dtype=float)
B = np.array([[0, 0], [1, 0], [0, 0], [0, 1]], dtype=float)
A_TAU = np.diag([0.01, 0, 0.02, 0])
TAU = 0.2
E = np.eye(2)
F = 0.5 * np.ones((2, 4))
K_NF = np.array([[-4.4453, -4.8047, -1.4766, -1.5234], [-1.4766, -1.5234, -4.4453, -4.8047]])
K_NORMAL = np.array([[-2.9687, -3.2813, 0, 0], [0, 0, -2.9687, -3.2813]])
GAINS = {'K_nf': K_NF, 'K_normal': K_NORMAL}


def count_zeros(A0, A1, tau, re_min, radius, points=40000):
    """Argument principle: zeros of det T(s) in the box re_min < Re s < re_min + radius,
    |Im s| < radius (independent of the discretization)."""
    a, b = re_min, re_min + radius
    t = np.linspace(0.0, 1.0, points // 4, endpoint=False)
    edges = [a - 1j * radius + (b - a) * t, b + 1j * radius * (2 * t - 1),
             b + 1j * radius - (b - a) * t, a + 1j * radius * (1 - 2 * t)]
    s = np.concatenate(edges + [edges[0][:1]])
    n = A0.shape[0]
    T = s[:, None, None] * np.eye(n) - A0 - A1 * np.exp(-s * tau)[:, None, None]
    phase = np.unwrap(np.angle(np.linalg.det(T)))
    return int(round((phase[-1] - phase[0]) / (2 * math.pi)))


def root_bound(A0, A1, tau, re_min):
    """Every root with Re s >= re_min has |s| <= this."""
    return np.linalg.norm(A0, 2) + np.linalg.norm(A1, 2) * math.exp(-re_min * tau)


# ----------------------------------------------------------------------------- delay-free
@pytest.mark.parametrize('shift', [-1.0, 0.7])
def test_zero_delay_matrix_is_eig(shift):
    rng = np.random.default_rng(3)
    M = rng.standard_normal((5, 5))
    A0 = M - (np.max(np.linalg.eigvals(M).real) - shift) * np.eye(5)   # abscissa == shift
    r = rightmost_roots(A0, np.zeros((5, 5)), 0.3)
    ev = np.linalg.eigvals(A0)
    assert abs(r.abscissa - ev.real.max()) < 1e-10
    assert abs(r.abscissa - shift) < 1e-10
    assert r.N == 0 and r.converged
    assert abs(spectral_abscissa(A0, np.zeros((5, 5)), 1.0) - ev.real.max()) < 1e-10
    assert is_stable(A0, np.zeros((5, 5)), 0.3) == (shift < 0)
    # tau = 0: eig(A0 + A1)
    A1 = rng.standard_normal((5, 5))
    r0 = rightmost_roots(A0, A1, 0.0, count=5)
    ev0 = np.linalg.eigvals(A0 + A1)
    assert abs(r0.abscissa - ev0.real.max()) < 1e-10
    assert np.allclose(np.sort_complex(r0.roots), np.sort_complex(ev0), atol=1e-12)


# ----------------------------------------------------------------------------- scalar cases
def test_scalar_negative_feedback_stability_boundary():
    b = 2.0
    assert spectral_abscissa([[0.0]], [[-b]], 1.5 / b) < 0
    assert spectral_abscissa([[0.0]], [[-b]], 1.6 / b) > 0
    assert is_stable([[0.0]], [[-b]], 1.5 / b)
    assert not is_stable([[0.0]], [[-b]], 1.6 / b)
    tau = math.pi / (2 * b)
    r = rightmost_roots([[0.0]], [[-b]], tau)
    assert abs(r.roots[0] - 1j * math.pi / (2 * tau)) < 1e-8
    assert abs(r.roots[1] + 1j * math.pi / (2 * tau)) < 1e-8
    assert abs(r.abscissa) < 1e-12
    assert not is_stable([[0.0]], [[-b]], tau)            # on the axis: not stable
    assert abs(delay_margin([[0.0]], [[-b]]) - math.pi / 4) < 1e-6
    assert abs(delay_margin([[0.0]], [[-b]]) - math.pi / 4) < 1e-12   # refined to round-off


@pytest.mark.parametrize('a, tau', [(-1.0, 1.0), (-2.0, 0.3), (0.5, 2.0), (-0.2, 1.0),
                                    (-50.0, 1.0), (-3.0, 0.05)])
def test_lambert_w_rightmost_root(a, tau):
    """x' = a x(t - tau): roots W_k(a tau) / tau; the principal branch is rightmost."""
    r = rightmost_roots([[0.0]], [[a]], tau)
    exact = complex(lambertw(a * tau, 0)) / tau
    assert abs(r.roots[0] - exact) < 1e-9 * max(1.0, abs(exact))
    assert abs(r.abscissa - exact.real) < 1e-9 * max(1.0, abs(exact))
    assert r.converged and np.all(r.residuals < 1e-10)
    # every returned root is some branch W_k
    for s in r.roots:
        assert min(abs(s - complex(lambertw(a * tau, k)) / tau) for k in range(-4, 5)) \
            < 1e-8 * max(1.0, abs(s))


def test_lambert_w_branches_in_order():
    a, tau = -1.0, 1.0
    r = rightmost_roots([[0.0]], [[a]], tau, count=5)
    exact = sorted((complex(lambertw(a * tau, k)) / tau for k in range(-3, 4)),
                   key=lambda z: (-z.real, -z.imag))[:5]
    assert np.allclose(r.roots[:5], exact, rtol=0, atol=1e-9)


def test_scalar_with_undelayed_term():
    """x' = a0 x + a1 x(t - tau): s = a0 + W_0(a1 tau exp(-a0 tau)) / tau."""
    a0, a1, tau = -0.5, -2.0, 0.7
    exact = a0 + complex(lambertw(a1 * tau * math.exp(-a0 * tau), 0)) / tau
    r = rightmost_roots([[a0]], [[a1]], tau)
    assert abs(r.roots[0] - exact) < 1e-9


def test_residuals_tiny_and_roots_independent_of_N():
    rng = np.random.default_rng(7)
    A0 = rng.standard_normal((4, 4)) - 2 * np.eye(4)
    A1 = rng.standard_normal((4, 4))
    r = rightmost_roots(A0, A1, 0.5, count=6)
    assert r.converged
    assert np.all(r.residuals < 1e-10)
    assert np.all(np.diff(r.roots.real) <= 1e-12)               # sorted
    assert np.allclose(np.sort_complex(r.roots), np.sort_complex(r.roots.conj()))
    for N in (40, 64):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', RuntimeWarning)
            rN = rightmost_roots(A0, A1, 0.5, count=6, N=N)
        assert abs(rN.abscissa - r.abscissa) < 1e-10
    # argument principle: nothing to the right of the abscissa, the rightmost roots just left
    R = root_bound(A0, A1, 0.5, r.abscissa - 1e-3) + 1
    assert count_zeros(A0, A1, 0.5, r.abscissa + 1e-6, R) == 0
    nright = 1 if r.roots[0].imag == 0 else 2
    assert count_zeros(A0, A1, 0.5, r.abscissa - 1e-3, R) == nright


# ----------------------------------------------------------------------------- delay margin
def test_delay_margin_two_states_against_scan():
    A0 = np.array([[-1.0, 0.0], [0.0, -2.0]])
    A1 = np.array([[0.5, 1.0], [-2.0, 0.3]])
    tm = delay_margin(A0, A1)
    assert 3.0 < tm < 4.0
    assert is_stable(A0, A1, tm * (1 - 1e-6))
    assert spectral_abscissa(A0, A1, tm * (1 - 1e-6)) < 0
    assert spectral_abscissa(A0, A1, tm * (1 + 1e-6)) > 0
    r = rightmost_roots(A0, A1, tm)
    assert abs(r.abscissa) < 1e-10 and abs(r.roots[0].imag) > 0
    grid = np.linspace(0.01, tm, 60, endpoint=False)       # stable on the whole interval
    assert all(is_stable(A0, A1, t) for t in grid)


def test_delay_margin_special_cases():
    # x' = -x - 2 x(t - tau): omega = sqrt(3), tau = acos(-1/2) / sqrt(3)
    assert abs(delay_margin([[-1.0]], [[-2.0]]) - math.acos(-0.5) / math.sqrt(3)) < 1e-12
    assert delay_margin([[-2.0]], [[1.0]]) == math.inf         # delay-independent
    assert delay_margin([[1.0]], [[-0.5]]) == 0.0              # unstable at tau = 0
    assert delay_margin([[-1.0]], [[0.0]]) == math.inf
    assert delay_margin([[0.0]], [[-2.0]], tau_max=0.5) == math.inf
    for K in GAINS.values():
        assert delay_margin(A + B @ K, A_TAU) == math.inf      # paper: small A_tau


# ----------------------------------------------------------------------------- fragility
@pytest.mark.parametrize('k, f', [(3.0, 0.4), (3.0, 4.0)])
def test_fragility_margin_scalar_closed_form(k, f):
    # x' = (-k + alpha f Delta) x: alpha = k / f (above and below the first trial 1)
    r = fragility_margin([[0.0]], [[1.0]], [[-k]], [[0.0]], 0.1, [[1.0]], [[f]])
    assert isinstance(r, FragilityResult)
    assert abs(r.alpha - k / f) < 1e-3 * k / f
    assert r.alpha <= r.alpha_upper <= r.alpha * (1 + 1e-5)
    assert abs(r.worst_abscissa - (-k + f)) < 1e-12
    assert r.worst_delta.shape == (1, 1) and abs(r.worst_delta[0, 0] - 1.0) < 1e-9
    again = fragility_margin([[0.0]], [[1.0]], [[-k]], [[0.0]], 0.1, [[1.0]], [[f]])
    assert again.alpha == r.alpha and again.evaluations == r.evaluations   # deterministic
    # nominally unstable: 0; never destabilized: inf
    assert fragility_margin([[1.0]], [[1.0]], [[0.0]], [[0.0]], 0.1, [[1.0]], [[f]]).alpha == 0.0
    assert fragility_margin([[0.0]], [[1.0]], [[-k]], [[0.0]], 0.1, [[1.0]], [[0.0]],
                            alpha_max=10.0).alpha == math.inf


@pytest.mark.parametrize('c, tau', [(0.5, 0.4), (2.0, 1.0)])
def test_fragility_margin_scalar_with_delay(c, tau):
    """x' = (-k + alpha Delta) x - c x(t - tau), k > c, worst Delta = +1, a0 = alpha - k.

    For a0 in (-c, c) a root crosses at s = i c sin(phi), a0 = c cos(phi), when
    phi / sin(phi) = c tau; that needs c tau > 1.  Otherwise the loop is lost
    only at a0 = c (root at s = 0)."""
    k = 3.0
    if c * tau <= 1.0:
        exact = k + c
    else:
        phi = brentq(lambda p: p / math.sin(p) - c * tau, 1e-9, math.pi - 1e-9)
        exact = k + c * math.cos(phi)
    r = fragility_margin([[0.0]], [[1.0]], [[-k]], [[-c]], tau, [[1.0]], [[1.0]])
    assert abs(r.alpha - exact) < 1e-5 * exact
    assert abs(r.worst_delta[0, 0] - 1.0) < 1e-9


def mu_real(M):
    """Real structured singular value for a full real block (Qiu et al. 1995)."""
    R, I = M.real, M.imag
    if np.linalg.norm(I) <= 1e-14 * max(1.0, np.linalg.norm(R)):
        return np.linalg.svd(R, compute_uv=False)[0]

    def f(lg):
        g = math.exp(lg)
        return np.linalg.svd(np.block([[R, -g * I], [I / g, R]]), compute_uv=False)[1]
    res = minimize_scalar(f, bounds=(math.log(1e-8), 0.0), method='bounded',
                          options={'xatol': 1e-9})
    return min(res.fun, f(0.0))


def real_stability_radius(K, omegas):
    """1 / sup_w mu_R(F T_K(i w)^-1 B E), T_K(s) = sI - A - BK - A_tau exp(-s tau)."""
    A0 = A + B @ K
    vals = [mu_real(F @ np.linalg.solve(1j * w * np.eye(4) - A0 - A_TAU * np.exp(-1j * w * TAU),
                                        B @ E)) for w in omegas]
    return 1.0 / max(vals), omegas[int(np.argmax(vals))]


# ----------------------------------------------------------------------------- the paper
PAPER = {}


def paper_numbers(name):
    """Compute (and cache) everything reported for one of the paper's gains."""
    if name not in PAPER:
        K = GAINS[name]
        out = {}
        for label, d in (('-I', -np.eye(2)), ('+I', np.eye(2))):
            out[label] = rightmost_roots(closed_loop_matrix(A, B, K, E, F, d), A_TAU, TAU)
        out['worst'] = worst_case_abscissa(A, B, K, A_TAU, TAU, E, F)
        out['frag'] = fragility_margin(A, B, K, A_TAU, TAU, E, F)
        PAPER[name] = out
    return PAPER[name]


@pytest.mark.parametrize('name', list(GAINS))
@pytest.mark.parametrize('label', ['-I', '+I'])
def test_paper_abscissa_argument_principle(name, label):
    r = paper_numbers(name)[label]
    K = GAINS[name]
    d = -np.eye(2) if label == '-I' else np.eye(2)
    A0 = closed_loop_matrix(A, B, K, E, F, d)
    assert r.converged and np.all(r.residuals < 1e-10)
    # independent: high-N discretization without the adaptive logic
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        assert abs(rightmost_roots(A0, A_TAU, TAU, N=64, count=2).abscissa - r.abscissa) < 1e-10
    # independent: no zero of det T(s) right of the abscissa, the rightmost ones just left
    R = root_bound(A0, A_TAU, TAU, r.abscissa - 1e-3) + 1
    assert count_zeros(A0, A_TAU, TAU, r.abscissa + 1e-6, R) == 0
    nright = 1 if r.roots[0].imag == 0 else 2
    assert count_zeros(A0, A_TAU, TAU, r.abscissa - 1e-3, R) == nright
    print(f'{name} Delta={label}: abscissa {r.abscissa:.10f}, rightmost {r.roots[0]:.6f}')


# values computed by this module and cross-checked in the tests below
EXPECTED = {  # (abscissa Delta=-I, abscissa Delta=+I, worst case at alpha=1, fragility alpha)
    'K_nf': (-1.0909753981, -1.1624320777, -1.0909201319, 5.9157009736),
    'K_normal': (-1.3207487506, -1.1335987607, -1.1335931315, 2.9639301027),
}


@pytest.mark.parametrize('name', list(GAINS))
def test_paper_numbers(name):
    p = paper_numbers(name)
    ex = EXPECTED[name]
    assert abs(p['-I'].abscissa - ex[0]) < 1e-9
    assert abs(p['+I'].abscissa - ex[1]) < 1e-9
    worst, D = p['worst']
    assert np.linalg.norm(D, 2) <= 1 + 1e-12
    assert worst >= max(p['-I'].abscissa, p['+I'].abscissa) - 1e-12
    assert abs(worst - ex[2]) < 1e-7
    assert abs(spectral_abscissa(closed_loop_matrix(A, B, GAINS[name], E, F, D), A_TAU, TAU)
               - worst) < 1e-12
    frag = p['frag']
    assert abs(frag.alpha - ex[3]) < 1e-5 * ex[3]
    assert abs(frag.worst_abscissa - worst) < 1e-12
    # the reported destabilizing perturbation really destabilizes at alpha_upper
    D_hi = frag.worst_delta
    assert np.linalg.norm(D_hi, 2) <= 1 + 1e-12
    assert spectral_abscissa(closed_loop_matrix(A, B, GAINS[name], E, F, frag.alpha_upper * D_hi),
                             A_TAU, TAU) >= -1e-10
    print(f'{name}: worst abscissa {worst:.10f}, fragility alpha {frag.alpha:.10f} '
          f'({frag.evaluations} evaluations)')


def test_paper_worst_case_dense_scan():
    """F has rank one (rows 0.5 * ones), so Delta F = w 0.5 1^T with w = Delta [1, 1]^T,
    ||w|| <= sqrt 2: a dense scan of that disc gives the worst case independently."""
    for name, K in GAINS.items():
        best = -math.inf
        for rad in np.linspace(0.0, math.sqrt(2), 4)[1:]:
            for th in np.linspace(0.0, 2 * math.pi, 64, endpoint=False):
                w = rad * np.array([math.cos(th), math.sin(th)])
                D = np.outer(w, [0.5, 0.5])                  # ||D||_2 = ||w|| / sqrt 2 <= 1
                best = max(best, spectral_abscissa(closed_loop_matrix(A, B, K, E, F, D),
                                                   A_TAU, TAU))
        worst = paper_numbers(name)['worst'][0]
        assert best <= worst + 1e-12
        assert worst - best < 1e-3


def test_paper_fragility_against_real_stability_radius():
    """The exact margin is the real stability radius of F T_K^-1 B E (Qiu et al. 1995);
    for both gains the supremum is at omega = 0, i.e. 1 / ||F (A + BK + A_tau)^-1 B E||."""
    omegas = np.concatenate([[0.0], np.logspace(-2, 2, 120)])
    for name, K in GAINS.items():
        r, w_peak = real_stability_radius(K, omegas)
        assert w_peak == 0.0
        closed = 1.0 / np.linalg.norm(F @ np.linalg.solve(A + B @ K + A_TAU, B @ E), 2)
        assert abs(r - closed) < 1e-12 * closed
        frag = paper_numbers(name)['frag']
        assert abs(frag.alpha - closed) < 1e-5 * closed
        assert frag.alpha_upper >= closed * (1 - 1e-9)   # cannot be below the exact margin
        assert abs(EXPECTED[name][3] - closed) < 1e-9


# ----------------------------------------------------------------------------- misc API
def test_closed_loop_matrix():
    D = np.array([[0.3, -0.2], [0.1, 0.4]])
    assert np.allclose(closed_loop_matrix(A, B, K_NF), A + B @ K_NF)
    assert np.allclose(closed_loop_matrix(A, B, K_NF, E, F, D), A + B @ (K_NF + E @ D @ F))
    assert np.allclose(closed_loop_matrix(A, B, K_NF, Delta=np.ones((2, 4))),
                       A + B @ (K_NF + np.ones((2, 4))))


def test_result_types_and_count():
    r = rightmost_roots([[0.0]], [[-1.0]], 1.0, count=3)
    assert isinstance(r, RootsResult)
    assert len(r.roots) == 4          # roots 3 and 4 are a conjugate pair: not split
    with pytest.raises(Exception):
        r.abscissa = 0.0                                   # frozen


# ----------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize('call, word', [
    (lambda: rightmost_roots(np.eye(2), np.eye(3), 0.1), 'A1'),
    (lambda: rightmost_roots(np.ones((2, 3)), np.eye(2), 0.1), 'A0'),
    (lambda: rightmost_roots(np.eye(2), np.eye(2), -0.1), 'tau'),
    (lambda: rightmost_roots(np.eye(2), np.eye(2), math.nan), 'tau'),
    (lambda: rightmost_roots([[math.inf]], [[0.0]], 0.1), 'A0'),
    (lambda: rightmost_roots([[1.0]], [[0.0]], 0.1, count=0), 'count'),
    (lambda: spectral_abscissa([[1.0]], [['x']], 0.1), 'A1'),
    (lambda: is_stable([[1.0]], [[1j]], 0.1), 'A1'),
    (lambda: delay_margin(np.eye(2), np.eye(3)), 'A1'),
    (lambda: delay_margin(np.eye(2), np.eye(2), tau_max=-1), 'tau_max'),
    (lambda: closed_loop_matrix(A, B, np.ones((2, 3))), 'K'),
    (lambda: closed_loop_matrix(A, B, K_NF, E, F, np.ones((3, 3))), 'Delta'),
    (lambda: worst_case_abscissa(A, B, K_NF, A_TAU, TAU, np.eye(3), F), 'E'),
    (lambda: fragility_margin(A, B, K_NF, A_TAU, TAU, E, np.ones((2, 3))), 'F'),
    (lambda: fragility_margin(A, B, K_NF, np.eye(3), TAU, E, F), 'A_tau'),
    (lambda: fragility_margin(A, B[:3], K_NF, A_TAU, TAU, E, F), 'B'),
    (lambda: fragility_margin(A, B, K_NF, A_TAU, -1.0, E, F), 'tau'),
])
def test_bad_inputs_raise_value_error(call, word):
    with pytest.raises(ValueError, match=word):
        call()
