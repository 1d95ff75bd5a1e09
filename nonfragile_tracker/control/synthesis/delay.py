"""Exact stability analysis of the delayed closed loop (plain numpy / scipy, no ROS).

The closed loop of the paper (eq. 7) with a *constant* gain perturbation is a linear
retarded delay system.  This module computes its rightmost characteristic roots
(:func:`rightmost_roots`), spectral abscissa (:func:`spectral_abscissa`) and stability
(:func:`is_stable`), the delay margin from the exact imaginary-axis crossings
(:func:`delay_margin`), and a *measured* fragility margin (:func:`fragility_margin`, inner
search :func:`worst_case_abscissa`).  Nothing is conservative, but the measured margin can
only err on the optimistic side, and only constant ``Delta`` are covered.

See doc/theory.md, section "Exact analysis of the delay loop".
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable, cast

import numpy as np
import scipy.linalg as sla

from ..validate import as_matrix, as_square

__all__ = ['RootsResult', 'FragilityResult', 'closed_loop_matrix', 'rightmost_roots',
           'spectral_abscissa', 'is_stable', 'delay_margin', 'worst_case_abscissa',
           'fragility_margin', 'clear_caches']

N_MIN = 16          # smallest discretization degree used by the adaptive rule
N_MAX = 192         # largest discretization degree the adaptive rule will use
RES_TOL = 1e-9      # a refined root is accepted iff its relative residual is below this
STABLE_TOL = 1e-10  # is_stable: abscissa < -STABLE_TOL
DENSE_MAX = 160     # generator size n (N+1) up to which a dense eig is used


# ----------------------------------------------------------------------------- validation

def _delay(tau: Any, name: str = 'tau') -> float:
    try:
        t = float(tau)
    except (TypeError, ValueError):
        raise ValueError(f'{name}: expected a real number, got {tau!r}') from None
    if not math.isfinite(t) or t < 0.0:
        raise ValueError(f'{name}: expected a finite number >= 0, got {tau!r}')
    return t


def _pair(A0: Any, A1: Any, tau: Any) -> tuple[np.ndarray, np.ndarray, float]:
    a0 = as_square(A0, 'A0')
    return a0, as_square(A1, 'A1', a0.shape[0]), _delay(tau)


def _loop(A: Any, B: Any, K: Any, A_tau: Any, tau: Any, E: Any, F: Any
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray,
                     np.ndarray]:
    a = as_square(A, 'A')
    n = a.shape[0]
    b = as_matrix(B, 'B', (n, None))
    m = b.shape[1]
    k = as_matrix(K, 'K', (m, n))
    a1 = as_square(A_tau, 'A_tau', n)
    e = as_matrix(E, 'E', (m, None))
    f = as_matrix(F, 'F', (None, n))
    return a, b, k, a1, _delay(tau), e, f


# ----------------------------------------------------------------------------- closed loop

def closed_loop_matrix(A: Any, B: Any, K: Any, E: Any = None, F: Any = None,
                       Delta: Any = None) -> np.ndarray:
    """Return ``A + B (K + E Delta F)``, the undelayed closed-loop matrix ``A0``.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    K : array_like, shape (m, n)
        State feedback gain, ``u = K xi``.
    E : array_like, shape (m, q), optional
        Defaults to the identity of size ``m``.
    F : array_like, shape (r, n), optional
        Defaults to the identity of size ``n``.
    Delta : array_like, shape (q, r), optional
        Constant gain perturbation; ``None`` means no perturbation.

    Returns
    -------
    A0 : ndarray, shape (n, n)

    Raises
    ------
    ValueError
        If a matrix is not finite or has the wrong shape (the message names it).
    """
    a = as_square(A, 'A')
    n = a.shape[0]
    b = as_matrix(B, 'B', (n, None))
    m = b.shape[1]
    k = as_matrix(K, 'K', (m, n))
    e = np.eye(m) if E is None else as_matrix(E, 'E', (m, None))
    f = np.eye(n) if F is None else as_matrix(F, 'F', (None, n))
    if Delta is None:
        return cast(np.ndarray, a + b @ k)
    d = as_matrix(Delta, 'Delta', (e.shape[1], f.shape[0]))
    return cast(np.ndarray, a + b @ (k + e @ d @ f))


# ----------------------------------------------------------------------------- roots

@dataclass(frozen=True)
class RootsResult:
    """Rightmost characteristic roots of ``det(s I - A0 - A1 exp(-s tau)) = 0``.

    Attributes
    ----------
    roots : ndarray of complex
        Roots sorted by decreasing real part (then decreasing imaginary part);
        complex roots appear with their conjugate.
    residuals : ndarray of float
        ``sigma_min(T(s)) / (|s| + ||A0|| + ||A1|| |exp(-s tau)|)`` at each root.
    abscissa : float
        Largest real part (the spectral abscissa); ``-inf`` only for ``n = 0``.
    N : int
        Chebyshev degree of the discretization used (0: delay-free, solved by ``eig``).
    converged : bool
        ``True`` iff the discretization resolves every root with a real part
        ``>= roots[-1].real`` (so no root is missing from the list) and every
        discretized eigenvalue in that region refined to a root within 1e-6
        (relative).
    """

    roots: np.ndarray
    residuals: np.ndarray
    abscissa: float
    N: int
    converged: bool


@lru_cache(maxsize=32)
def _cheb(N: int) -> np.ndarray:
    """Chebyshev differentiation matrix on the extremal nodes cos(j pi / N) (Trefethen)."""
    x = np.cos(np.pi * np.arange(N + 1) / N)
    c = np.hstack([2.0, np.ones(N - 1), 2.0]) * (-1.0) ** np.arange(N + 1)
    dx = x[:, None] - x[None, :]
    D = np.outer(c, 1.0 / c) / (dx + np.eye(N + 1))
    D -= np.diag(D.sum(axis=1))
    D.setflags(write=False)
    return D


def chebyshev_differentiation(N: int) -> np.ndarray:
    """Chebyshev differentiation matrix on ``cos(j pi / N)``, ``j = 0..N`` (read-only, cached).

    Parameters
    ----------
    N : int
        Degree (``N + 1`` nodes).
    """
    return _cheb(N)


@lru_cache(maxsize=64)
def _cheb_resolvent(N: int, tau: float, sigma: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Shift-invert pieces of the Chebyshev differentiation matrix (cached, read-only).

    ``G = (Dt[1:, 1:] - sigma I)^-1``, ``d0 = Dt[1:, 0]`` and ``c = G[-1] @ d0``, with
    ``Dt = (2 / tau) D_N`` (see :class:`_ShiftInvert`).
    """
    Dt = _cheb(N) * (2.0 / tau)
    G = np.linalg.inv(Dt[1:, 1:] - sigma * np.eye(N))
    d0 = np.ascontiguousarray(Dt[1:, 0])
    G.setflags(write=False)
    d0.setflags(write=False)
    return G, d0, float(G[-1] @ d0)


def _generator(A0: np.ndarray, A1: np.ndarray, tau: float, N: int) -> np.ndarray:
    """BMV discretization of the infinitesimal generator, size n (N+1).

    Nodes ``theta_j = tau (cos(j pi / N) - 1) / 2``: ``theta_0 = 0``, ``theta_N = -tau``.
    """
    n = A0.shape[0]
    M = np.kron(_cheb(N) * (2.0 / tau), np.eye(n))
    M[:n, :] = 0.0
    M[:n, :n] = A0
    M[:n, -n:] += A1
    return M


def _n_needed(radius: float, tau: float) -> int:
    """Degree resolving every root of modulus <= radius (exp(s theta) on [-tau, 0])."""
    rt = radius * tau
    if not math.isfinite(rt):
        return N_MAX + 1
    return max(N_MIN, int(math.ceil(12 + 1.2 * rt)))


class _Char:
    """Characteristic matrix T(s) = s I - A0 - A1 exp(-s tau) and Newton refinement."""

    def __init__(self, A0: np.ndarray, A1: np.ndarray, tau: float) -> None:
        self.A0, self.A1, self.tau = A0, A1, tau
        self.n = A0.shape[0]
        self.I = np.eye(self.n)
        self.nrm0 = float(np.linalg.norm(A0, 2)) if self.n else 0.0
        self.nrm1 = float(np.linalg.norm(A1, 2)) if self.n else 0.0
        self._bounds: tuple[float, float] | None = None
        self._eigen: tuple[np.ndarray, list[np.ndarray]] | None = None

    @property
    def hmax(self) -> float:
        """``lambda_max((A0 + A0^T) / 2)`` (computed on first use)."""
        return self._numerical_range()[0]

    @property
    def skew(self) -> float:
        """``||(A0 - A0^T) / 2||_2`` (computed on first use)."""
        return self._numerical_range()[1]

    def eigen(self) -> tuple[np.ndarray, list[np.ndarray]]:
        """Eigenvalues of A0 and disc radii for ``M = V^-1 A1 V`` (``V`` its eigenvectors).

        Gershgorin row and column sums of ``|M|`` and Bauer-Fike ``||M||_2``, each plus a
        round-off allowance
        ``1e-12 cond(V) (||A0|| + ||A1||)``; no radii if ``V`` is numerically singular
        (computed on first use).
        """
        if self._eigen is None:
            radii: list[np.ndarray] = []
            lam = np.zeros(0, complex)
            if self.n:
                try:
                    lam, V = np.linalg.eig(self.A0)
                    cond = float(np.linalg.cond(V))
                    if cond < 1e8:
                        M = np.linalg.solve(V, self.A1 @ V)
                        slack = 1e-12 * cond * (self.nrm0 + self.nrm1)
                        Ma = np.abs(M)
                        radii = [Ma.sum(axis=1) + slack, Ma.sum(axis=0) + slack,
                                 np.full(self.n, np.linalg.norm(M, 2) + slack)]
                except np.linalg.LinAlgError:
                    pass
            self._eigen = (lam, radii)
        return self._eigen

    def _numerical_range(self) -> tuple[float, float]:
        if self._bounds is None:
            A0 = self.A0
            self._bounds = ((float(np.linalg.eigvalsh(0.5 * (A0 + A0.T))[-1]),
                             float(np.linalg.norm(0.5 * (A0 - A0.T), 2)))
                            if self.n else (0.0, 0.0))
        return self._bounds

    def T(self, s: complex) -> np.ndarray:
        return cast(np.ndarray, s * self.I - self.A0 - self.A1 * np.exp(-s * self.tau))

    def dT(self, s: complex) -> np.ndarray:
        return cast(np.ndarray, self.I + (self.tau * np.exp(-s * self.tau)) * self.A1)

    def residual(self, s: complex) -> float:
        sv = np.linalg.svd(self.T(s), compute_uv=False)
        scale = abs(s) + self.nrm0 + self.nrm1 * abs(np.exp(-s * self.tau))
        return float(sv[-1] / scale) if scale > 0 else float(sv[-1])

    def vectors(self, s: complex) -> tuple[np.ndarray, np.ndarray]:
        """Left and right singular vectors of the smallest singular value of T(s)."""
        U, _, Vh = np.linalg.svd(self.T(s))
        return U[:, -1], Vh[-1].conj()

    def newton(self, s0: complex, maxit: int = 40) -> tuple[complex, float]:
        """Newton on the bordered system [T(s) v; c^H v - 1] = 0; returns (s, residual).

        A real start is iterated in real arithmetic (the root stays exactly real).
        A diverging iteration returns an infinite residual.
        """
        with np.errstate(over='ignore', invalid='ignore'):
            try:
                return self._newton(s0, maxit)
            except np.linalg.LinAlgError:
                return s0, math.inf

    def _newton(self, s0: complex, maxit: int) -> tuple[complex, float]:
        real = isinstance(s0, float) or np.imag(s0) == 0.0
        s = float(np.real(s0)) if real else complex(s0)
        _, v = self.vectors(s)
        if real:
            v = np.real(v)
            v /= np.linalg.norm(v)
        c = v.conj()
        n = self.n
        J = np.zeros((n + 1, n + 1), dtype=float if real else complex)
        rhs = np.zeros(n + 1, dtype=J.dtype)
        small, prev = 0, math.inf
        for _ in range(maxit):
            J[:n, :n] = self.T(s)
            J[:n, n] = self.dT(s) @ v
            J[n, :n] = c
            rhs[:n] = -(J[:n, :n] @ v)
            rhs[n] = 1.0 - c @ v
            try:
                d = np.linalg.solve(J, rhs)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(d)):
                return s, math.inf
            v = v + d[:n]
            s = s + d[n].item()
            if self.tau * -np.real(s) > 700.0:      # exp(-s tau) would overflow
                return s, math.inf
            step = abs(d[n].item()) / max(1.0, abs(s))
            if step <= 1e-12 or (step < 1e-8 and step >= prev):   # converged / round-off
                small += 1
                if small >= 2:
                    break
            prev = step
        if not np.isfinite(s):
            return s, math.inf
        return s, self.residual(s)


def _sort_key(s: complex) -> tuple[float, float]:
    return (-s.real, -s.imag)


def _truncate(roots: list[complex], count: int) -> list[complex]:
    """First ``count`` roots, extended so that a conjugate pair is never split."""
    if len(roots) <= count:
        return roots
    k = count
    last = roots[k - 1]
    while k < len(roots) and last.imag > 0 and abs(roots[k] - np.conj(last)) <= \
            1e-12 * max(1.0, abs(last)):
        k += 1
    return roots[:k]


def _delay_free(ch: _Char, M: np.ndarray, count: int) -> RootsResult:
    ev = sorted((complex(z) for z in np.linalg.eigvals(M)), key=_sort_key)
    ev = _truncate(ev, count)
    res = [ch.residual(z) for z in ev]
    return RootsResult(np.array(ev, dtype=complex), np.array(res), max(z.real for z in ev),
                       0, True)


def _resolved_radius(N: int, tau: float) -> float:
    """Inverse of :func:`_n_needed`: modulus up to which degree N resolves the roots."""
    return (N - 12) / (1.2 * tau)


def _radius(ch: _Char, re: float) -> float:
    """Bound on |s| for every root with Re s >= re.

    A root is ``s = v^H A0 v + z v^H A1 v`` (``T(s) v = 0``, ``|v| = 1``,
    ``z = exp(-s tau)``, ``|z| <= exp(-re tau) =: e``), so
    ``Re s <= h + ||A1|| e`` (``h = lambda_max(He A0 / 2)``),
    ``|Im s| <= ||(A0 - A0^T) / 2|| + ||A1|| e`` and ``|s| <= ||A0|| + ||A1|| e``;
    the smaller of the disc and of the rectangle ``[re, Re max] x [-Im max, Im max]``'s
    farthest corner.
    """
    z = math.exp(min(-re * ch.tau, 700.0))
    e = ch.nrm1 * z
    re_hi, im_hi = ch.hmax + e, ch.skew + e
    if re_hi < re:
        return 0.0
    bound = min(ch.nrm0 + e, math.hypot(max(abs(re), abs(re_hi)), im_hi))
    # V^-1 (A0 + z A1) V = L + z M (V the eigenvectors of A0, M = V^-1 A1 V): every root
    # lies in a disc |s - lambda_i| <= |z| r_i, r_i the Gershgorin row (or column) sums of
    # |M| or Bauer-Fike's ||M||_2; only discs reaching Re >= re matter, which keeps fast
    # stable modes out
    lam, radii = ch.eigen()
    for r in radii:
        rho = r * z
        keep = lam.real + rho >= re
        bound = min(bound, float(np.max(np.abs(lam[keep]) + rho[keep])) if keep.any() else 0.0)
    return bound


class _ShiftInvert:
    """``(M - sigma I)^-1 b`` for the generator ``M`` of :func:`_generator` in O(n N^2 + n^2).

    With ``X`` the ``(N+1, n)`` node-major reshape of ``x`` and ``Dt = (2/tau) D_N``,
    rows ``1..N`` give ``X[1:] = G (B[1:] - d0 x0^T)`` with
    ``G = (Dt[1:, 1:] - sigma I)^-1`` and ``d0 = Dt[1:, 0]``; hence
    ``x_N = g^T B[1:] - c x0`` (``g`` the last row of ``G``, ``c = g^T d0``) and row 0,
    ``(A0 - sigma I) x0 + A1 x_N = b0``, is the n x n system
    ``(A0 - sigma I - c A1) x0 = b0 - A1 B[1:]^T g``.
    """

    def __init__(self, ch: _Char, N: int, sigma: float) -> None:
        n = ch.n
        self.G, self.d0, c = _cheb_resolvent(N, ch.tau, sigma)
        self.g = self.G[-1]
        S = ch.A0 - sigma * np.eye(n) - c * ch.A1
        self.lu = sla.lu_factor(S, check_finite=False)
        piv = np.abs(np.diag(self.lu[0]))
        self.ok = bool(np.all(np.isfinite(self.G)) and piv.min() > 1e-13 * max(piv.max(), 1.0))
        self.A1, self.N, self.n = ch.A1, N, n

    def __call__(self, b: np.ndarray) -> np.ndarray:
        B = b.reshape(self.N + 1, self.n)
        x0 = sla.lu_solve(self.lu, B[0] - self.A1 @ (self.g @ B[1:]), check_finite=False)
        X1 = self.G @ (B[1:] - np.outer(self.d0, x0))
        return np.concatenate([x0, X1.ravel()])


def _generator_eigs(ch: _Char, N: int, k: int) -> tuple[np.ndarray, float]:
    """Eigenvalues of the generator: all of them (dense) or the ``k`` nearest a shift.

    Returns ``(ev, covered)``: every eigenvalue of modulus ``< covered`` is in
    ``ev`` (``covered = inf`` for the dense solve).  Small matrices (``n (N+1) <=
    DENSE_MAX``) or ``k`` close to the size use LAPACK; otherwise shift-invert
    Arnoldi (``scipy.sparse.linalg.eigs`` on :class:`_ShiftInvert`) returns the
    ``k`` eigenvalues nearest ``sigma`` (0, or a small real shift if ``0`` is
    too close to an eigenvalue): the disc ``|lambda - sigma| < rho_k`` holds no
    other eigenvalue, so ``covered = rho_k - |sigma|``.
    """
    size = ch.n * (N + 1)
    if size > DENSE_MAX and k < size // 3:
        from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, LinearOperator, eigs
        scale = max(ch.nrm0 + ch.nrm1, 1e-300)
        for sigma in (0.0, 1e-2 * scale, -3e-2 * scale):
            op = _ShiftInvert(ch, N, sigma)
            if not op.ok:
                continue
            lin = LinearOperator((size, size), matvec=op, dtype=float)
            try:
                # Ritz values to 1e-8 (relative) suffice: Newton refines every root
                mu = eigs(lin, k=k, which='LM', return_eigenvectors=False, tol=1e-8,
                          v0=np.ones(size) / math.sqrt(size))
            except (ArpackError, ArpackNoConvergence):
                break
            mu = mu[mu != 0]
            if mu.size == 0 or not np.all(np.isfinite(mu)):
                break
            ev = sigma + 1.0 / mu
            rho = float(np.max(np.abs(ev - sigma)))
            up = ev[ev.imag >= 0]           # a pair may be cut at the disc's edge: keep
            lo = ev[ev.imag < 0].conj()     # one member of each, with Im >= 0
            lo = [z for z in lo if up.size == 0 or np.min(np.abs(up - z)) > 1e-8 * abs(z)]
            ev = np.concatenate([up, np.asarray(lo, dtype=complex)])
            return ev, rho * (1.0 - 1e-9) - abs(sigma)
    return np.linalg.eigvals(_generator(ch.A0, ch.A1, ch.tau, N)), math.inf


def _roots_at(ch: _Char, N: int, count: int) -> tuple[list[complex], list[float], bool]:
    """Discretize with degree N, refine the rightmost eigenvalues; (roots, residuals, agree).

    Only eigenvalues inside the resolved disc are used (the discretization also
    has spurious eigenvalues of large modulus).  Candidates are refined in order
    of decreasing real part until ``count`` roots are found and the remaining
    candidates lie to their left.  ``agree`` is false if a candidate to the
    right of the last returned root failed to refine or moved by more than
    1e-6 (relative).  With the shift-invert solver the number ``k`` of
    eigenvalues computed is doubled until they cover the disc
    ``|s| <= 1.05 R(a)`` that holds every root right of the last returned one
    (``a`` its real part, ``R`` of :func:`_radius`), or the resolved disc.
    """
    r_res = _resolved_radius(N, ch.tau)
    key = (ch.n, N, count)
    k = _K_USED.get(key, max(2 * count + 10, 2 * ch.n + 12))
    while True:
        ev, covered = _generator_eigs(ch, N, k)
        out, resid, agree = _refine(ch, ev[np.abs(ev) <= r_res], count)
        need = r_res if not out else min(r_res, 1.05 * _radius(ch, out[-1].real) + 1e-9)
        if covered >= need or math.isinf(covered):
            if not math.isinf(covered):
                if len(_K_USED) > 256:
                    _K_USED.clear()
                _K_USED[key] = k
            return out, resid, agree
        k = 2 * k


# degree that converged last time, per (n, tau, count): the start of the adaptive rule
_N_USED: dict[tuple[int, float, int], int] = {}


def clear_caches() -> None:
    """Forget the remembered degrees and Arnoldi sizes (the next call starts afresh)."""
    _N_USED.clear()
    _K_USED.clear()


# k that covered the needed disc last time, per (n, N, count): margin and worst-case
# searches evaluate many nearby loops of one shape, so the first call learns it
_K_USED: dict[tuple[int, int, int], int] = {}


def _refine(ch: _Char, ev: np.ndarray, count: int) -> tuple[list[complex], list[float], bool]:
    """Newton-refine candidate eigenvalues in order of decreasing real part (see _roots_at)."""
    ev = ev[np.argsort(-ev.real, kind='stable')]
    found: list[complex] = []          # distinct roots with Im >= 0
    resid: list[float] = []
    bad: list[float] = []              # real parts of candidates that failed / jumped
    for z in ev:
        if z.imag < 0:
            continue
        nfound = sum(1 if r.imag == 0 else 2 for r in found)
        if nfound >= count:
            last = min(r.real for r in found)
            if z.real < last - 1e-6 * max(1.0, abs(z)):
                break
        s, r = ch.newton(z)
        if r > RES_TOL and z.imag == 0.0:     # near-double real pair: try complex Newton
            s, r = ch.newton(complex(z.real, 1e-6 * max(1.0, abs(z))))
        if r > RES_TOL:
            bad.append(z.real)
            continue
        s = complex(s)
        if abs(s.imag) <= 1e-14 * max(1.0, abs(s)):
            s = complex(s.real, 0.0)
        elif s.imag < 0:
            s = s.conjugate()
        if abs(s - z) > 1e-6 * max(1.0, abs(s)):
            bad.append(z.real)
        if not any(abs(s - u) <= 1e-8 * max(1.0, abs(u)) for u in found):
            found.append(s)
            resid.append(r)
    roots: list[tuple[complex, float]] = []
    for s, r in zip(found, resid):
        roots.append((s, r))
        if s.imag > 0:
            roots.append((s.conjugate(), r))
    roots.sort(key=lambda t: _sort_key(t[0]))
    out = _truncate([t[0] for t in roots], count)
    k = len(out)
    agree = k > 0 and not any(b >= out[-1].real - 1e-6 * max(1.0, abs(out[-1])) for b in bad)
    return out, [t[1] for t in roots[:k]], agree


def _rightmost(A0: np.ndarray, A1: np.ndarray, tau: float, count: int = 6,
               N: int | None = None, warn: bool = True) -> RootsResult:
    ch = _Char(A0, A1, tau)
    if ch.n == 0:
        return RootsResult(np.zeros(0, complex), np.zeros(0), -math.inf, 0, True)
    if tau == 0.0:
        ch = _Char(A0 + A1, np.zeros_like(A1), 0.0)
        return _delay_free(ch, A0 + A1, count)
    if not np.any(A1):
        return _delay_free(ch, A0, count)
    adaptive = N is None
    key = (ch.n, tau, count)
    if N is None:
        N = _N_USED.get(key)
        if N is None:
            # resolve R(a0), a0 a guess of the last wanted root's real part from the
            # delay-free matrix A0 + A1 (only a start: the loop below checks);
            # capped because the loop raises N when needed
            re = np.sort(np.linalg.eigvals(A0 + A1).real)[::-1]
            a0 = min(0.0, float(re[min(count, re.size) - 1]))
            N = min(_n_needed(_radius(ch, a0), tau), 64)
    N = int(N)
    retried = False
    while True:
        roots, resid, agree = _roots_at(ch, N, count)
        # complete iff every root right of the last one returned lies in the resolved disc
        need = _n_needed(_radius(ch, roots[-1].real), tau) if roots else 2 * N
        ok = agree and N >= need
        if not adaptive or N >= N_MAX:
            break
        if not ok:
            N = min(N_MAX, max(need, N + 8))
        elif len(roots) < count and not retried:   # more roots may lie outside the disc
            retried = True
            N = min(N_MAX, 2 * N)
        else:
            break
    if adaptive and ok:
        if len(_N_USED) > 256:
            _N_USED.clear()
        _N_USED[key] = N
    if not roots:
        raise RuntimeError(f'rightmost_roots: no characteristic root could be refined (N={N})')
    absc = max(z.real for z in roots)
    if warn and not ok:
        warnings.warn(f'rightmost_roots: not converged at N={N} (abscissa {absc:.6g}); '
                      'the result may miss roots', RuntimeWarning, stacklevel=3)
    return RootsResult(np.array(roots, dtype=complex), np.array(resid), float(absc), N, ok)


def rightmost_roots(A0: Any, A1: Any, tau: float, *, count: int = 6,
                    N: int | None = None) -> RootsResult:
    """Rightmost roots of ``det(s I - A0 - A1 exp(-s tau)) = 0``.

    Parameters
    ----------
    A0, A1 : array_like, shape (n, n)
        Undelayed and delayed system matrices of ``x' = A0 x + A1 x(t - tau)``.
    tau : float
        Delay, ``>= 0``.
    count : int, optional
        Number of roots wanted (default 6); one more is returned if the last
        one would split a conjugate pair.  Fewer are returned if the resolved
        region (see Notes) holds fewer after one doubling of ``N``.
    N : int, optional
        Chebyshev degree of the discretization.  Default: adaptive (see Notes).

    Returns
    -------
    RootsResult
        ``roots``, ``residuals``, ``abscissa``, ``N`` and ``converged``.  A
        ``RuntimeWarning`` is issued when ``converged`` is false.

    Raises
    ------
    ValueError
        Bad shapes, non-finite entries, negative or non-finite ``tau``, ``count < 1``.

    Notes
    -----
    The infinitesimal generator of the delay equation is discretized by
    pseudospectral collocation on the ``N + 1`` Chebyshev extremal nodes of
    ``[-tau, 0]`` [1]_; the eigenvalues of that ``n (N+1)`` matrix with the
    largest real parts are each refined by Newton's method on the bordered
    system ``T(s) v = 0, c^H v = 1`` (``T(s) = s I - A0 - A1 exp(-s tau)``, ``c``
    the starting null vector) [2]_.  Refined roots whose relative residual
    exceeds ``1e-9`` are dropped and coincident ones merged, so in the delay
    case each distinct root is listed once (multiplicity is not reported).

    Adaptive degree: any root with ``Re s >= a`` satisfies ``|s| <= R(a)``, the
    smaller of ``||A0|| + ||A1|| e`` and the farthest corner of the rectangle
    ``a <= Re s <= lambda_max(He A0 / 2) + ||A1|| e``,
    ``|Im s| <= ||(A0 - A0^T) / 2|| + ||A1|| e`` (``e = exp(-a tau)``; numerical-range
    bounds), and of the discs ``|s - lambda_i| <= e r_i`` around the eigenvalues of
    ``A0`` that reach ``Re s >= a`` (``r_i`` Gershgorin or Bauer-Fike radii of
    ``V^-1 A1 V``, ``V`` the eigenvectors of ``A0``), which keeps fast stable modes of
    stiff loops out of the degree.  ``exp(s theta)`` on ``[-tau, 0]`` is resolved for
    ``|s| <= R`` by
    ``N >= 12 + 1.2 R tau`` (at least 16), and only discretized eigenvalues inside that
    disc are used (the discretization also has spurious ones of large modulus).  The
    degree starts from ``R(a0)``, ``a0`` a guess from the eigenvalues of ``A0 + A1`` and
    ``A0`` (at most 64), or from the degree that converged on the previous call for the
    same ``(n, tau, count)``, and is raised, up to 192, until it covers ``R(a)`` for ``a``
    the real part of the last returned root and every discretized eigenvalue right of
    ``a`` refined to a root within ``1e-6`` (relative); ``converged`` reports whether
    that succeeded.  An explicit ``N`` disables the adaptation.

    Eigenvalues: a generator of size ``n (N+1) <= 160`` is solved densely (LAPACK).
    Larger ones use shift-invert Arnoldi (ARPACK via ``scipy.sparse.linalg.eigs``) at
    ``sigma = 0`` with a structured solve of ``(M - sigma I) x = b`` in
    ``O(n N^2 + n^2)`` (one ``n x n`` LU per call): the ``k`` eigenvalues nearest
    ``sigma`` fill a disc that holds no other eigenvalue, and ``k`` is doubled until
    that disc covers ``1.05 R(a)``.  The ``k`` that sufficed is remembered per shape,
    so the many calls of margin and worst-case searches start from it.

    ``tau == 0`` is solved as ``eig(A0 + A1)`` and ``A1 == 0`` as ``eig(A0)``
    (``N = 0``; roots repeated with multiplicity, as LAPACK returns them).

    References
    ----------
    .. [1] D. Breda, S. Maset, R. Vermiglio, "Pseudospectral differencing
       methods for characteristic roots of delay differential equations",
       SIAM J. Sci. Comput. 27(2):482-495, 2005.
    .. [2] W. Michiels, S.-I. Niculescu, "Stability, Control, and Computation
       for Time-Delay Systems: An Eigenvalue-Based Approach", 2nd ed.,
       SIAM, 2014.

    Examples
    --------
    >>> r = rightmost_roots([[0.0]], [[-2.0]], math.pi / 4)   # x' = -2 x(t - pi/4)
    >>> bool(abs(r.roots[0] - 2j) < 1e-12 and abs(r.roots[1] + 2j) < 1e-12)
    True
    """
    a0, a1, t = _pair(A0, A1, tau)
    if not _is_int(count, 1):
        raise ValueError(f'count: expected an integer >= 1, got {count!r}')
    if N is not None and not _is_int(N, 2):
        raise ValueError(f'N: expected an integer >= 2, got {N!r}')
    return _rightmost(a0, a1, t, int(count), None if N is None else int(N))


def _is_int(value: Any, minimum: int) -> bool:
    try:
        return bool(int(value) == value and value >= minimum)
    except (TypeError, ValueError):
        return False


def spectral_abscissa(A0: Any, A1: Any, tau: float, **kw: Any) -> float:
    """Largest real part of the characteristic roots (see :func:`rightmost_roots`).

    Parameters
    ----------
    A0, A1 : array_like, shape (n, n)
    tau : float
    **kw
        Passed to :func:`rightmost_roots` (``count``, ``N``).

    Returns
    -------
    float
    """
    kw.setdefault('count', 2)
    return rightmost_roots(A0, A1, tau, **kw).abscissa


def is_stable(A0: Any, A1: Any, tau: float, *, tol: float = STABLE_TOL) -> bool:
    """Exponential stability of ``x' = A0 x + A1 x(t - tau)``.

    Parameters
    ----------
    A0, A1 : array_like, shape (n, n)
    tau : float
    tol : float, optional
        Margin (default 1e-10).

    Returns
    -------
    bool
        ``spectral_abscissa(A0, A1, tau) < -tol``: roots on (or within ``tol``
        of) the imaginary axis count as unstable.
    """
    return spectral_abscissa(A0, A1, tau) < -tol


# ----------------------------------------------------------------------------- delay margin

def _crossing_candidates(A0: np.ndarray, A1: np.ndarray, unit_tol: float = 1e-5
                         ) -> list[tuple[float, float]]:
    """Imaginary-axis crossings ``(omega > 0, smallest delay tau_0)``.

    ``s = i omega`` is a root for delay ``tau`` iff ``i omega`` is an eigenvalue
    of ``A0 + A1 z`` with ``z = exp(-i omega tau)``; then ``-i omega`` is one of
    ``A0 + A1 / z`` and ``0`` one of the Kronecker sum, i.e. ``z`` solves the
    quadratic eigenvalue problem ``(z^2 A1 (x) I + z (A0 (x) I + I (x) A0) + I (x) A1) u = 0``.
    """
    n = A0.shape[0]
    I = np.eye(n)
    M2 = np.kron(A1, I)
    M1 = np.kron(A0, I) + np.kron(I, A0)
    M0 = np.kron(I, A1)
    nn = n * n
    Z = np.zeros((nn, nn))
    In = np.eye(nn)
    L = np.block([[Z, In], [-M0, -M1]])
    R = np.block([[In, Z], [Z, M2]])
    ab = sla.eig(L, R, right=False, homogeneous_eigvals=True)
    alpha, beta = ab[0], ab[1]
    scale = float(np.linalg.norm(A0, 2) + np.linalg.norm(A1, 2))
    out: list[tuple[float, float]] = []
    for a, b in zip(alpha, beta):
        if abs(b) == 0.0 or not np.isfinite(a / b):
            continue
        z = a / b
        if abs(abs(z) - 1.0) > unit_tol:
            continue
        z = z / abs(z)
        for lam in np.linalg.eigvals(A0 + A1 * z):
            if abs(lam.real) > 1e-5 * max(1.0, scale) or lam.imag <= 1e-12 * max(1.0, scale):
                continue
            w = lam.imag
            phi = (-np.angle(z)) % (2.0 * math.pi)
            out.append((w, phi / w))
    return out


def _refine_crossing(A0: np.ndarray, A1: np.ndarray, w: float, tau0: float) -> float:
    """Secant on tau for Re s(tau) = 0, s tracked by Newton from i omega."""
    def g(t: float, s0: complex) -> tuple[float, complex]:
        c = _Char(A0, A1, t)
        s, r = c.newton(s0)
        if r > RES_TOL:
            raise ArithmeticError
        return float(np.real(s)), complex(s)
    try:
        t0, t1 = tau0, tau0 * (1.0 + 1e-6) + 1e-12
        g0, s0 = g(t0, 1j * w)
        g1, s1 = g(t1, s0)
        for _ in range(30):
            if abs(g1) <= 1e-14 * max(1.0, abs(s1)) or g1 == g0:
                break
            t0, t1, g0 = t1, t1 - g1 * (t1 - t0) / (g1 - g0), g1
            g1, s1 = g(t1, s1)
        if abs(t1 - tau0) <= 1e-3 * max(tau0, 1e-12) and abs(g1) <= 1e-9 * max(1.0, abs(s1)):
            return t1
    except (ArithmeticError, ValueError, np.linalg.LinAlgError):
        pass
    return tau0


def delay_margin(A0: Any, A1: Any, *, tau_max: float = math.inf) -> float:
    """Delay margin of ``x' = A0 x + A1 x(t - tau)``.

    Parameters
    ----------
    A0, A1 : array_like, shape (n, n)
    tau_max : float, optional
        Only delays up to ``tau_max`` are considered (default: all).

    Returns
    -------
    float
        The largest ``tau_m`` such that the system is exponentially stable for
        every ``tau`` in ``[0, tau_m)``; equivalently the smallest delay at
        which a characteristic root lies on the imaginary axis.  ``0.0`` if the
        system is not stable at ``tau = 0`` (``A0 + A1`` not Hurwitz);
        ``math.inf`` if it is stable for every ``tau <= tau_max``.

    Raises
    ------
    ValueError
        Bad shapes or entries, ``tau_max`` negative or NaN.

    Notes
    -----
    For a retarded system roots can only enter the right half-plane through
    the imaginary axis as ``tau`` grows.  ``s = i omega`` is a root for delay
    ``tau`` iff ``i omega`` is an eigenvalue of ``A0 + A1 z``,
    ``z = exp(-i omega tau)``; conjugating, ``0`` is then an eigenvalue of the
    Kronecker sum ``(A0 + A1 z) (+) (A0 + A1 / z)``, which is a quadratic
    eigenvalue problem in ``z`` of size ``n^2`` [1]_.  Its unimodular
    solutions give every crossing frequency ``omega > 0`` and the smallest
    crossing delay ``(-arg z mod 2 pi) / omega``; each is checked against
    ``eig(A0 + A1 z)`` (the Kronecker sum has spurious zeros
    ``lambda_i = -conj(lambda_j)``) and refined to full precision by a secant
    iteration on ``Re s(tau) = 0`` with ``s`` tracked by Newton's method.  The
    pencil is regular whenever ``A0 + A1`` is Hurwitz (its determinant at
    ``z = 1`` is nonzero).  ``omega = 0`` is impossible then
    (``det(A0 + A1) != 0``).  Unimodularity is tested with tolerance
    ``1e-5``.

    References
    ----------
    .. [1] J. Chen, G. Gu, C. N. Nett, "A new method for computing delay
       margins for stability of linear delay systems", Systems & Control
       Letters 26(2):107-117, 1995.
    """
    a0 = as_square(A0, 'A0')
    a1 = as_square(A1, 'A1', a0.shape[0])
    try:
        tmax = float(tau_max)
    except (TypeError, ValueError):
        raise ValueError(f'tau_max: expected a number, got {tau_max!r}') from None
    if math.isnan(tmax) or tmax < 0:
        raise ValueError(f'tau_max: expected a delay >= 0, got {tau_max!r}')
    if a0.shape[0] == 0:
        return math.inf
    if not np.all(np.linalg.eigvals(a0 + a1).real < -STABLE_TOL):
        return 0.0
    if not np.any(a1):
        return math.inf
    best = math.inf
    for w, t0 in sorted(_crossing_candidates(a0, a1), key=lambda c: c[1]):
        if t0 > min(best, tmax) * (1 + 1e-3) + 1e-12:
            break
        t = _refine_crossing(a0, a1, w, t0)
        best = min(best, t)
    return best if best <= tmax else math.inf


# ----------------------------------------------------------------------------- fragility

class _Perturbed:
    """Spectral abscissa of A + B (K + scale E Delta F) with A_tau, and its gradient in Delta."""

    def __init__(self, A: np.ndarray, B: np.ndarray, K: np.ndarray, A_tau: np.ndarray,
                 tau: float, E: np.ndarray, F: np.ndarray) -> None:
        self.A0 = A + B @ K
        self.BE = B @ E
        self.F = F
        self.A1, self.tau = A_tau, tau
        self.shape = (E.shape[1], F.shape[0])
        self.evaluations = 0

    def __call__(self, Delta: np.ndarray, scale: float) -> tuple[float, np.ndarray]:
        self.evaluations += 1
        A0 = self.A0 + scale * (self.BE @ Delta @ self.F)
        res = _rightmost(A0, self.A1, self.tau, count=1, N=None, warn=False)
        s = complex(res.roots[0])
        ch = _Char(A0, self.A1, self.tau)
        u, v = ch.vectors(s)
        den = u.conj() @ ch.dT(s) @ v
        if den == 0:
            return res.abscissa, np.zeros(self.shape)
        grad = np.real(scale * np.outer(u.conj() @ self.BE, self.F @ v) / den)
        return res.abscissa, grad


def _project(M: np.ndarray) -> np.ndarray:
    """Nearest point of the unit spectral-norm ball (clip singular values at 1)."""
    U, S, Vt = np.linalg.svd(M, full_matrices=False)
    return cast(np.ndarray, (U * np.minimum(S, 1.0)) @ Vt)


def _candidates(shape: tuple[int, int], rng: np.random.Generator, n_random: int
                ) -> list[np.ndarray]:
    q, r = shape
    p = min(q, r)
    out: list[np.ndarray] = []
    if p <= 4:
        for signs in range(2 ** p):
            d = np.array([1.0 if (signs >> i) & 1 else -1.0 for i in range(p)])
            M = np.zeros(shape)
            M[:p, :p] = np.diag(d)
            out.append(M)
    else:
        out += [np.eye(q, r), -np.eye(q, r)]
    for _ in range(n_random):
        U, _, Vt = np.linalg.svd(rng.standard_normal(shape), full_matrices=False)
        out.append(U @ Vt)
        a, b = rng.standard_normal(q), rng.standard_normal(r)
        out.append(np.outer(a / np.linalg.norm(a), b / np.linalg.norm(b)))
    return out


def _ascent(f: Callable[[np.ndarray, float], tuple[float, np.ndarray]], D: np.ndarray,
            val: float, grad: np.ndarray, scale: float, maxit: int
            ) -> tuple[float, np.ndarray]:
    """Projected gradient ascent of the abscissa on the unit ball (adaptive step)."""
    step = 0.25
    for _ in range(maxit):
        gn = np.linalg.norm(grad)
        if gn == 0.0 or step < 1e-7:
            break
        C = _project(D + (step / gn) * grad)
        if np.linalg.norm(C - D) < 1e-9:
            break
        cv, cg = f(C, scale)
        if cv > val + 1e-13:
            D, val, grad = C, cv, cg
            step = min(2.0 * step, 2.0)
        else:
            step *= 0.5
    return val, D


def _search(f: _Perturbed, scale: float, rng: np.random.Generator, *, n_random: int,
            n_starts: int, maxit: int, warm: list[np.ndarray] | None = None
            ) -> tuple[float, np.ndarray]:
    """Evaluate the candidates (and warm starts), ascend from the best distinct ones."""
    pool = list(warm or []) + _candidates(f.shape, rng, n_random)
    evals = []
    for D in pool:
        v, g = f(D, scale)
        evals.append((v, D, g))
    evals.sort(key=lambda t: -t[0])
    best_v, best_D = evals[0][0], evals[0][1]
    starts: list[tuple[float, np.ndarray, np.ndarray]] = []
    for t in evals:
        if len(starts) >= n_starts:
            break
        if all(np.linalg.norm(t[1] - s[1]) > 1e-6 for s in starts):
            starts.append(t)
    for v, D, g in starts:
        v, D = _ascent(f, D, v, g, scale, maxit)
        if v > best_v:
            best_v, best_D = v, D
    return best_v, best_D


def worst_case_abscissa(A: Any, B: Any, K: Any, A_tau: Any, tau: float, E: Any, F: Any,
                        scale: float = 1.0, seed: int = 0, *, n_random: int = 8,
                        n_starts: int = 3, maxit: int = 60) -> tuple[float, np.ndarray]:
    """Largest spectral abscissa found over constant ``||Delta||_2 <= 1``.

    The loop is ``xi' = (A + B (K + scale E Delta F)) xi + A_tau xi(t - tau)``.

    Parameters
    ----------
    A, B, K, A_tau : array_like
        Shapes (n, n), (n, m), (m, n), (n, n).
    tau : float
        Delay ``>= 0``.
    E, F : array_like
        Shapes (m, q) and (r, n); ``Delta`` is (q, r).
    scale : float, optional
        Perturbation scale ``>= 0`` (default 1).
    seed : int, optional
        Seed of the random candidates; the result is deterministic given it.
    n_random, n_starts, maxit : int, optional
        Random orthogonal and rank-one candidates (each), number of local
        ascents, iterations per ascent.

    Returns
    -------
    abscissa : float
        Largest spectral abscissa found.
    Delta : ndarray, shape (q, r)
        The maximizer found (``||Delta||_2 <= 1``).

    Notes
    -----
    Candidates: all sign-diagonal matrices (``+-I`` and mixed signs, if
    ``min(q, r) <= 4``), ``n_random`` random orthogonal and ``n_random``
    random rank-one ``a b^T`` (unit ``a, b``).  The best ``n_starts`` start a
    projected gradient ascent on the unit ball (projection = clipping the
    singular values at 1), with the gradient of the rightmost root
    ``d Re s / d Delta = Re(scale (B E)^T conj(u) (F v)^T / (u^H T'(s) v))``
    (``u``, ``v`` left/right null vectors of ``T(s)``).  This is a local
    search: the value is a lower bound of the true worst case.
    """
    a, b, k, a1, t, e, f = _loop(A, B, K, A_tau, tau, E, F)
    sc = _delay(scale, 'scale')
    f_ = _Perturbed(a, b, k, a1, t, e, f)
    rng = np.random.default_rng(seed)
    return _search(f_, sc, rng, n_random=n_random, n_starts=n_starts, maxit=maxit)


@dataclass(frozen=True)
class FragilityResult:
    """Measured fragility margin (see :func:`fragility_margin`).

    Attributes
    ----------
    alpha : float
        Largest scale at which the search found no destabilizing ``Delta``
        (``math.inf`` if none up to ``alpha_max``; ``0.0`` if the nominal loop
        is unstable).
    alpha_upper : float
        Smallest scale at which a destabilizing ``Delta`` was found
        (``alpha <= alpha_upper <= alpha (1 + rtol)``); ``inf`` if none.
    worst_delta : ndarray
        Shape ``(q, r)``: ``||Delta||_2 <= 1`` with ``A + B (K + alpha_upper E Delta F)`` not
        exponentially stable (abscissa ``>= -1e-10``); at ``alpha = inf`` the
        worst case found at ``alpha_max``; zero if the nominal loop is unstable.
    worst_abscissa : float
        Worst-case spectral abscissa found over ``||Delta||_2 <= 1`` at scale 1.
    worst_delta_at_1 : ndarray
        Its maximizer, shape ``(q, r)``.
    evaluations : int
        Number of spectral-abscissa evaluations.
    """

    alpha: float
    alpha_upper: float
    worst_delta: np.ndarray
    worst_abscissa: float
    worst_delta_at_1: np.ndarray
    evaluations: int


def _unstable(v: float) -> bool:
    """A worst-case abscissa ``v`` that counts as unstable (the :func:`is_stable` convention)."""
    return v >= -STABLE_TOL


_Bracket = tuple[float, float, float, float, np.ndarray]


def _grow_bracket(w: Callable[[float], tuple[float, np.ndarray]], nominal: float, w1: float,
                  D1: np.ndarray, amax: float) -> _Bracket:
    """``[lo, hi]`` with ``w(lo) < 0 <= w(hi)`` from ``[0, 1]`` (:func:`fragility_margin`).

    Grown by linear extrapolation, x1.25 to x4 per step, up to ``amax`` (where ``w(hi)``
    may still be stable).  Returns ``(lo, w(lo), hi, w(hi), maximizer at hi)``.
    """
    lo, w_lo, hi, w_hi, D_hi = 0.0, nominal, 1.0, w1, D1
    while not _unstable(w_hi):
        if hi >= amax:
            break
        guess = hi - w_hi * (hi - lo) / (w_hi - w_lo) if w_hi > w_lo else 4.0 * hi
        x = min(amax, max(1.25 * hi, min(4.0 * hi, guess)))
        lo, w_lo = hi, w_hi
        hi, (w_hi, D_hi) = x, w(x)
    return lo, w_lo, hi, w_hi, D_hi


def _regula_falsi(w: Callable[[float], tuple[float, np.ndarray]], lo: float, w_lo: float,
                  hi: float, w_hi: float, D_hi: np.ndarray, rtol: float) -> _Bracket:
    """Illinois regula falsi on ``w`` with a bisection safeguard, to ``hi - lo <= rtol hi``."""
    side = 0
    while hi - lo > rtol * hi:
        x = hi - w_hi * (hi - lo) / (w_hi - w_lo) if w_hi != w_lo else 0.5 * (lo + hi)
        if not lo + 0.01 * (hi - lo) < x < hi - 0.01 * (hi - lo):
            x = 0.5 * (lo + hi)
        v, D = w(x)
        if _unstable(v):
            hi, w_hi, D_hi = x, v, D
            w_lo *= 0.5 if side == 1 else 1.0
            side = 1
        else:
            lo, w_lo = x, v
            w_hi *= 0.5 if side == -1 else 1.0
            side = -1
    return lo, w_lo, hi, w_hi, D_hi


def fragility_margin(A: Any, B: Any, K: Any, A_tau: Any, tau: float, E: Any, F: Any, *,
                     seed: int = 0, alpha_max: float = 1e3, rtol: float = 1e-6,
                     n_random: int = 8, n_starts: int = 3, maxit: int = 60
                     ) -> FragilityResult:
    """Measured fragility margin of the gain ``K`` against ``Delta K = alpha E Delta F``.

    Largest ``alpha`` such that ``xi' = (A + B (K + alpha E Delta F)) xi +
    A_tau xi(t - tau)`` is exponentially stable for every constant
    ``||Delta||_2 <= 1`` -- as *measured* by a worst-case search.

    Parameters
    ----------
    A, B, K, A_tau, tau, E, F
        As in :func:`worst_case_abscissa`.
    seed : int, optional
        Seed of the random candidates (deterministic given it).
    alpha_max : float, optional
        Largest scale tried (default 1e3); beyond it ``alpha = inf``.
    rtol : float, optional
        Relative width of the final bracket ``[alpha, alpha_upper]``.
    n_random, n_starts, maxit : int, optional
        Passed to the worst-case search (:func:`worst_case_abscissa`).

    Returns
    -------
    FragilityResult

    Notes
    -----
    ``w(alpha)`` = worst-case abscissa over ``||Delta|| <= 1`` at scale
    ``alpha`` is nondecreasing in ``alpha`` (nested balls), so the margin is the
    root of ``w`` ("unstable" meaning abscissa ``>= -1e-10``, as in
    :func:`is_stable`).  It is bracketed (``[0, 1]``, or grown from 1 by
    linear extrapolation, x1.25 to x4 per step) and located by regula falsi
    (Illinois variant) with a bisection safeguard.  ``w(1)`` and the final
    ``w(alpha)`` use the full worst-case search of
    :func:`worst_case_abscissa`; the intermediate steps a quick one (the
    sign-diagonal candidates plus the previous maximizers as warm starts,
    one ascent).  If the final full search destabilizes ``alpha``, the
    bracket is searched again with full searches.

    Honesty: instability at ``alpha_upper`` is *demonstrated* (``worst_delta``
    is an explicit destabilizing perturbation), so ``alpha_upper`` is a
    rigorous upper bound of the true margin (up to root-finding accuracy).
    Stability at ``alpha`` is only *measured*: a local search that misses the
    global worst case over-estimates the margin.  The true margin equals the
    real stability radius of ``F T_K(s)^{-1} B E`` (``T_K`` the nominal
    characteristic matrix) [1]_, which can be used as an independent check.
    Only constant ``Delta`` are covered; the LMI certificate of
    :mod:`.lmi` covers time-varying ``Delta(t)`` too.

    References
    ----------
    .. [1] L. Qiu, B. Bernhardsson, A. Rantzer, E. J. Davison, P. M. Young,
       J. C. Doyle, "A formula for computation of the real stability radius",
       Automatica 31(6):879-890, 1995.
    """
    a, b, k, a1, t, e, f = _loop(A, B, K, A_tau, tau, E, F)
    try:
        amax = float(alpha_max)
    except (TypeError, ValueError):
        amax = math.nan
    if not amax > 0:
        raise ValueError(f'alpha_max: expected a number > 0, got {alpha_max!r}')
    if not 0 < rtol < 1:
        raise ValueError(f'rtol: expected 0 < rtol < 1, got {rtol!r}')
    fn = _Perturbed(a, b, k, a1, t, e, f)
    rng = np.random.default_rng(seed)
    zero = np.zeros(fn.shape)
    full = dict(n_random=n_random, n_starts=n_starts, maxit=maxit)
    quick = dict(n_random=0, n_starts=1, maxit=maxit)
    warm: list[np.ndarray] = []

    def w(alpha: float, opts: dict[str, Any]) -> tuple[float, np.ndarray]:
        v, D = _search(fn, alpha, rng, warm=warm[-2:], **opts)
        warm.append(D)
        return v, D

    w1, D1 = w(1.0, full)
    nominal, _ = fn(zero, 0.0)
    if nominal >= -STABLE_TOL:
        return FragilityResult(0.0, 0.0, zero, w1, D1, fn.evaluations)

    # bracket [lo, hi]: w(lo) < 0 <= w(hi); grow by linear extrapolation (x1.25 .. x4)
    grown = _grow_bracket(lambda x: w(x, quick), nominal, w1, D1, amax)
    if not _unstable(grown[3]):         # stable up to alpha_max
        return FragilityResult(math.inf, math.inf, grown[4], w1, D1, fn.evaluations)
    lo, w_lo, hi, w_hi, D_hi = _regula_falsi(lambda x: w(x, quick), *grown, rtol)
    # confirm the stable end with the full search; if it finds instability there,
    # back off and locate again with full searches
    for _ in range(4):
        v, D = w(lo, full)
        if not _unstable(v):
            break
        hi, w_hi, D_hi = lo, v, D
        x = lo
        while _unstable(v) and x > 0:
            hi, w_hi, D_hi = x, v, D
            x *= 0.5
            v, D = w(x, full)
        lo, w_lo, hi, w_hi, D_hi = _regula_falsi(lambda x: w(x, full), x, v, hi, w_hi, D_hi,
                                                 rtol)
    return FragilityResult(lo, hi, D_hi, w1, D1, fn.evaluations)
