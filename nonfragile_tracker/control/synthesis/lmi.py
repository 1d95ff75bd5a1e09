"""Theorem 1 of the paper: non-fragile (and nominal) gain synthesis, certificates.

Closed loop (paper eq. 7)::

    xi' = (A + B (K + E D(t) F)) xi + A_tau xi(t - tau),   D^T D <= I.

The synthesis LMI (paper eq. 8/16) is solved in ``X = P^-1``, ``W = Q^-1``, ``R = K X``,
normalised by maximising its strictness; every returned gain passes an independent numpy
check (:func:`verify_certificate`), and a fixed ``K`` is certified by :func:`certify_gain`.

See doc/theory.md, section "Theorem 1: non-fragile synthesis and certificates" (#theorem-1):
the LMI, the normalisation, the verification matrix, Petersen's lemma; the synthesis
choices in the section after it.
"""
from __future__ import annotations

import contextvars
import time
import warnings
from dataclasses import dataclass, replace
from typing import Any, Sequence, cast

import numpy as np

from .errors import CertificateError, InfeasibleError, LmiError, SolverFailure
from .certificate import (CertifiedGain, eigen_figures, from_certificate, passes,
                          retry_advice)
from .certificate import Verification as BaseVerification
from .problem import Problem
from .sdp import DEFAULT_MARGIN, DEFAULT_SOLVER, OK_STATUSES, cached_program, classify, solve
from .sdp import sym as _sym

__all__ = ['LmiError', 'InfeasibleError', 'SolverFailure', 'CertificateError', 'Certificate',
           'Verification', 'SynthesisResult', 'CertifyResult', 'verify_certificate',
           'synthesize', 'certify_gain', 'certified_perturbation_scale',
           'UntrustedGainWarning', 'gain_trust_message', 'decoupled_blocks']


@dataclass(frozen=True)
class Verification(BaseVerification):
    """Outcome of :func:`verify_certificate` (:class:`.certificate.Verification`).

    Besides ``ok`` and the keywords ``tolerance`` and ``scale`` of the base:

    Parameters
    ----------
    max_eig_V : float
        Largest eigenvalue of ``V`` (must be ``< -tolerance * scale``).
    min_eig_P, min_eig_Q : float
        Smallest eigenvalues of ``P`` and ``Q`` (must be > 0).
    """

    max_eig_V: float
    min_eig_P: float
    min_eig_Q: float

    MATRIX = 'V'
    WORST = 'max_eig_V'
    POSITIVE = (('min_eig_P', 'P'), ('min_eig_Q', 'Q'))


@dataclass(frozen=True)
class Certificate:
    """Lyapunov-Krasovskii certificate of Theorem 1 for a gain ``K``.

    ``eps is None`` means the nominal (D = 0) condition.
    """

    K: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    eps: float | None
    verification: Verification


@dataclass(frozen=True, kw_only=True)
class SynthesisResult(CertifiedGain):
    """A synthesized gain with its verified certificate and solver facts.

    The fields are those of :class:`.certificate.CertifiedGain` (keywords), ``certificate``
    a :class:`Certificate`.
    """

    certificate: Certificate

    P = from_certificate('P', 'Lyapunov-Krasovskii matrix ``P`` of the certificate.')
    Q = from_certificate('Q', 'Lyapunov-Krasovskii matrix ``Q`` of the certificate.')
    eps = from_certificate('eps', 'Scalar ``eps`` of the certificate (None: the nominal '
                           'condition, D = 0).')


@dataclass(frozen=True)
class CertifyResult:
    """Whether Theorem 1's condition holds for a fixed ``K``."""

    certified: bool
    margin_achieved: float   # best t in normalized units (> 0 iff certified)
    certificate: Certificate | None
    status: str


def verification_matrix(A: np.ndarray, B: np.ndarray, A_tau: np.ndarray, E: np.ndarray,
                        F: np.ndarray, K: np.ndarray, P: np.ndarray, Q: np.ndarray,
                        eps: float | None) -> np.ndarray:
    """The matrix ``V`` of Theorem 1 (doc/theory.md #theorem-1), symmetric.

    Parameters
    ----------
    A, B, A_tau : numpy.ndarray
        The plant (``n x n``, ``n x m``, ``n x n``).
    E, F : numpy.ndarray
        The perturbation structure (``m x q``, ``p x n``).
    K : numpy.ndarray, shape (m, n)
        The gain.
    P, Q : numpy.ndarray, shape (n, n)
        The Lyapunov-Krasovskii matrices.
    eps : float or None
        Petersen's scalar; ``None``: the nominal form (``2n x 2n``, no ``E, F`` terms).

    Returns
    -------
    numpy.ndarray
        ``(2n + q) x (2n + q)``, or ``2n x 2n`` for the nominal form.
    """
    A0 = A + B @ K
    top = P @ A0 + A0.T @ P + Q
    n = A.shape[0]
    if eps is None:
        return _sym(np.block([[top, P @ A_tau], [A_tau.T @ P, -Q]]))
    q = E.shape[1]
    top = top + (F.T @ F) / eps
    PBE = P @ B @ E
    V = np.block([
        [top, P @ A_tau, PBE],
        [A_tau.T @ P, -Q, np.zeros((n, q))],
        [PBE.T, np.zeros((q, n)), -np.eye(q) / eps],
    ])
    return _sym(V)


def verify_certificate(problem: Problem, K: Any, P: Any, Q: Any, eps: float | None, *,
                       tol: float = 1e-9) -> Verification:
    """Check Theorem 1's condition from ``(K, P, Q, eps)`` alone, with eigenvalues.

    Passes iff ``P > 0``, ``Q > 0``, ``eps > 0`` (unless nominal) and
    ``max eig(V) < -tol * ||V||`` (:func:`.certificate.passes`).  Never raises for a
    failed check: see ``ok``.

    Parameters
    ----------
    problem : Problem
        The data ``A, B, A_tau, E, F``.
    K : array_like, shape (m, n)
        The gain (:meth:`.problem.Problem.gain` checks its shape).
    P, Q : array_like, shape (n, n)
        The Lyapunov-Krasovskii matrices (their symmetric parts are used).
    eps : float or None
        Petersen's scalar; ``None``: the nominal condition (``D = 0``).
    tol : float, optional
        Relative slack demanded of ``V``.

    Returns
    -------
    Verification
    """
    K = problem.gain(K)
    P = _sym(np.asarray(P, float))
    Q = _sym(np.asarray(Q, float))
    V = verification_matrix(problem.A, problem.B, problem.A_tau, problem.E, problem.F,
                            K, P, Q, eps)
    top, scale, (min_p, min_q) = eigen_figures(V, (P, Q))
    return Verification(passes(top, scale, (min_p, min_q), eps, tol), top, min_p, min_q,
                        tolerance=tol, scale=scale)


def _certificate(problem: Problem, K: np.ndarray, P: np.ndarray, Q: np.ndarray,
                 eps: float | None, verify_tol: float) -> Certificate:
    """``(K, P, Q, eps)`` with their :func:`verify_certificate` (``ok`` or not)."""
    ver = verify_certificate(problem, K, P, Q, eps, tol=verify_tol)
    return Certificate(K=K, P=P, Q=Q, eps=eps, verification=ver)


# ---------------------------------------------------------------------------------------------
# cvxpy problems, built once per shape and re-solved with new data (DPP parameters).

class _Theorem1Program:
    """Parametrized synthesis SDP for fixed (n, m, q, p) and nominal flag."""

    def __init__(self, n: int, m: int, q: int, p: int, nominal: bool, gain_bound: bool):
        import cvxpy as cp
        self.cp = cp
        self.nominal = nominal
        self.A = cp.Parameter((n, n), name='A')
        self.B = cp.Parameter((n, m), name='B')
        self.Ad = cp.Parameter((n, n), name='A_tau')
        self.X = cp.Variable((n, n), symmetric=True, name='X')
        self.W = cp.Variable((n, n), symmetric=True, name='W')
        self.R = cp.Variable((m, n), name='R')
        self.t = cp.Variable(name='t')
        S = self.A @ self.X + self.B @ self.R
        Z = np.zeros
        if nominal:
            blocks = [
                [S + S.T, self.Ad @ self.W, self.X],
                [(self.Ad @ self.W).T, -self.W, Z((n, n))],
                [self.X, Z((n, n)), -self.W],
            ]
            size = 3 * n
            self.eps = None
            norm = cp.trace(self.X) + cp.trace(self.W)
            extra = []
        else:
            self.BE = cp.Parameter((n, q), name='BE')
            self.F = cp.Parameter((p, n), name='F')
            self.eps = cp.Variable(name='eps')
            XFt = self.X @ self.F.T
            blocks = [
                [S + S.T, self.eps * self.BE, self.Ad @ self.W, self.X, XFt],
                [(self.eps * self.BE).T, -self.eps * np.eye(q), Z((q, n)), Z((q, n)), Z((q, p))],
                [(self.Ad @ self.W).T, Z((n, q)), -self.W, Z((n, n)), Z((n, p))],
                [self.X, Z((n, q)), Z((n, n)), -self.W, Z((n, p))],
                [XFt.T, Z((p, q)), Z((p, n)), Z((p, n)), -self.eps * np.eye(p)],
            ]
            size = 3 * n + q + p
            norm = cp.trace(self.X) + cp.trace(self.W) + self.eps
            extra = [self.eps >= self.t]
        self._maximize_strictness(blocks, size, norm, extra, n, m, gain_bound)

    def _maximize_strictness(self, blocks: list[Any], size: int, norm: Any, extra: list[Any],
                             n: int, m: int,
                             gain_bound: bool, lean: bool = False) -> None:
        """Maximize ``t``: ``LMI <= -t I``, ``X, W >= t I`` and the scale fixed (all forms).

        With ``gain_bound``, ``||K||_2 <= kappa``: ``X >= I`` and
        ``[[kappa^2 (2X - I), R^T], [R, I]] >= 0``, because ``X^2 >= 2X - I`` gives
        ``R^T R <= kappa^2 (2X - I) <= kappa^2 X^2``; the scale is then fixed by ``X >= I``,
        so the trace normalization is replaced by ``t <= 1``.

        ``lean`` leaves out PSD cones that are not needed (each costs the interior-point
        solver a dense ``svec`` block): ``W >= t I`` (``-W`` is a diagonal block of
        ``LMI <= -t I``) and, with ``gain_bound``, ``X >= t I`` and ``X >= I``: the second
        cone alone gives ``2X - I >= R^T R / kappa^2 >= 0``, i.e. ``X >= I / 2 > 0``
        (the scale fixed from below), and the bound needs only ``X > 0``:
        ``K^T K = X^-1 R^T R X^-1 <= kappa^2 (I - (I - X^-1)^2) <= kappa^2 I``.
        """
        cp = self.cp
        L = cp.bmat(blocks)
        L = 0.5 * (L + L.T)
        cons = [L << -self.t * np.eye(size)] + extra
        if not (lean and gain_bound):
            cons.append(self.X >> self.t * np.eye(n))
        if self.W is not None and not lean:
            cons.append(self.W >> self.t * np.eye(self.W.shape[0]))
        if gain_bound:
            self.kappa2 = cp.Parameter(nonneg=True, name='kappa2')
            G = cp.bmat([[self.kappa2 * (2 * self.X - np.eye(n)), self.R.T],
                         [self.R, np.eye(m)]])
            if not lean:
                cons.append(self.X >> np.eye(n))
            cons += [0.5 * (G + G.T) >> 0, self.t <= 1]
        else:
            self.kappa2 = None
            cons += [norm <= 1]
        self.problem = cp.Problem(cp.Maximize(self.t), cons)

    def set_data(self, problem: Problem, kappa: float | None = None) -> None:
        """Put ``problem``'s data (and the gain bound ``kappa``) into the parameters."""
        self.A.value = problem.A
        self.B.value = problem.B
        self.Ad.value = problem.A_tau
        if not self.nominal:
            self.BE.value = problem.B @ problem.E
            self.F.value = problem.F
        if self.kappa2 is not None:
            self.kappa2.value = float(cast(float, kappa)) ** 2   # given with gain_bound

    def point(self, status: str, solve_time: float) -> tuple[Any, ...]:
        """``(status, t, X, Q, R, eps, solve_time)`` with ``Q = W^-1`` (``None`` if singular)."""
        W = self.W.value
        try:
            Q = None if W is None else np.linalg.inv(_sym(W))
        except np.linalg.LinAlgError:
            Q = None
        return (status, self.t.value, self.X.value, Q, self.R.value,
                None if self.eps is None else self.eps.value, solve_time)

    #: compile the first solve without DPP (``sdp.solve(ignore_dpp=True)``), re-solves with it
    cold_first = False
    solves = 0

    def first_solve(self) -> bool:
        """Count a solve; ``True`` for the first one of a ``cold_first`` program."""
        self.solves += 1
        return self.cold_first and self.solves == 1

    def solve(self, problem: Problem, solver: str, kappa: float | None = None
              ) -> tuple[Any, ...]:
        """Solve for ``problem``: ``(status, t, X, Q, R, eps, solve_time)`` (see :meth:`point`)."""
        self.set_data(problem, kappa)
        out = solve(self.problem, solver, what=f'problem {problem.name!r}',
                    ignore_dpp=self.first_solve())
        return self.point(out.status, out.solve_time)


def _program(problem: Problem, nominal: bool, gain_bound: bool) -> _Theorem1Program:
    shape = (problem.n, problem.m, problem.E.shape[1], problem.F.shape[0], nominal, gain_bound)
    return cached_program(('theorem1',) + shape, lambda: _Theorem1Program(*shape))


def _synthesize_once(problem: Problem, *, nominal: bool = False, margin: float | None = None,
                     solver: str | None = None, gain_bound: float | None = None,
                     verify_tol: float = 1e-9) -> SynthesisResult:
    """One solve of Theorem 1 (or its nominal form), verified.

    The arguments are those of :func:`synthesize` (``margin``, ``solver`` default to the
    problem's options).  Raises ``InfeasibleError`` (no point with ``t >= margin``),
    ``SolverFailure`` (no solution) or ``CertificateError`` (the point fails
    :func:`verify_certificate`; ``margin_achieved`` holds the solver's ``t``).
    """
    margin = float(problem.options.get('margin', DEFAULT_MARGIN) if margin is None else margin)
    solver = str(problem.options.get('solver', DEFAULT_SOLVER) if solver is None else solver)
    if gain_bound is not None and not gain_bound > 0:
        raise ValueError(f'gain_bound must be > 0, got {gain_bound!r}')
    t0 = time.perf_counter()
    prog = _program_for(problem, nominal, gain_bound is not None)
    status, t, X, Q, R, eps, solve_time = prog.solve(problem, solver, gain_bound)
    kind = 'nominal' if nominal else 'non-fragile'
    verdict = classify(status, t, margin)
    if verdict == 'infeasible':
        best = 'no feasible point' if t is None else f'best margin t = {t:.3g}'
        bound = '' if gain_bound is None else f' with ||K||_2 <= {gain_bound:g}'
        raise InfeasibleError(
            f'Theorem 1 ({kind}{bound}) is infeasible for problem {problem.name!r}: {best} < '
            f'required margin {margin:g}. Try a smaller A_tau or F, a looser gain bound, the '
            'nominal design, or the delay-dependent design.')
    if verdict == 'failed' or X is None or Q is None:
        raise SolverFailure(f'solver {solver} returned status {status!r} for problem '
                            f'{problem.name!r}; no gain was produced')
    P = np.linalg.inv(_sym(X))
    K = R @ P
    cert = _certificate(problem, K, P, Q, None if nominal else float(eps), verify_tol)
    ver = cert.verification
    if not ver.ok:
        err = CertificateError(
            f'{solver} returned a point for {problem.name!r} ({kind}) that fails independent '
            f'verification: {ver.describe()} (||V|| = {ver.scale:.3g}, best margin '
            f't = {t:.3g}). ' + retry_advice(solver))
        err.margin_achieved = float(t)          # the solver's t, for synthesize's retries
        raise err
    return SynthesisResult(K=K, certificate=cert, margin_required=margin,
                           margin_achieved=float(t), status=status, solver=solver,
                           solve_time=solve_time, wall_time=time.perf_counter() - t0,
                           nominal=nominal,
                           extra={} if gain_bound is None else {'gain_bound': gain_bound})


# ---------------------------------------------------------------------------------------------
# Reduced form of Theorem 1 for larger n.

def _rank_split(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """SVD ``M = U diag(s) V^T`` and its numerical rank (``s > max(shape) eps s_max``)."""
    U, s, Vt = np.linalg.svd(M)
    tol = max(M.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0)
    return U, s, Vt, int(np.sum(s > tol)) if s.size and s[0] > 0 else 0


def _reduced_shape(problem: Problem) -> tuple[int, int]:
    """``(rank A_tau, rank F)``: the sizes the reduced LMI depends on."""
    return _rank_split(problem.A_tau)[3], _rank_split(problem.F)[3]


class _ReducedProgram(_Theorem1Program):
    """Theorem 1 with the rank of ``A_tau`` and ``F`` exploited: LMI of size ``n + r + p'``.

    Write ``A_tau = U M^T`` (``r = rank A_tau``) and ``F^T F = G^T G`` (``G`` is
    ``p' x n``, ``p' = rank F``).  The Schur complement of the module docstring's ``V``
    in ``X = P^-1`` coordinates is ::

        He(A X + B R) + eps B E E^T B^T + X Q X + X G^T G X / eps
                      + U M^T Q^-1 M U^T  < 0.

    Only ``M^T Q^-1 M`` (``r x r``) enters the delay term, so with ``W_r > 0``
    (``r x r``) and ``Q = M W_r^-1 M^T + (t / 2) P^2`` the condition holds iff ::

        [ He(A X + B R) + eps B E E^T B^T + U W_r U^T   X M    X G^T  ]
        [  *                                           -W_r    0      ]  < 0
        [  *                                            *     -eps I  ]

    Equivalence: given ``(X, Q)``, ``W_r = M^T Q^-1 M`` gives ``M W_r^-1 M^T <= Q``
    (so the ``X Q X`` term only shrinks) and the same delay term.  Conversely, for the
    ``Q`` above ``M^T Q^-1 M = (S^-1 + W_r^-1)^-1 <= W_r`` (Woodbury, ``S = M^T D^-1 M``,
    ``D = (t/2) P^2``), so the delay term only shrinks, and ``X D X = (t / 2) I`` uses
    half of the strictness ``LMI <= -t I`` (``Q`` is positive definite even when
    ``r < n``, and well away from singular when ``A_tau`` has tiny singular values).
    The ``E`` block is eliminated (it is linear in ``eps``).  The size ``n + r + p'`` is
    at most ``2n + p`` (full ranks) against ``2n + q + p`` for ``S = X Q X`` and
    ``3n + q + p`` for the paper's form; the interior-point solver's dense ``svec``
    block costs the sixth power of that size.

    The data are first rotated by the orthogonal ``T`` of the SVD ``A_tau = T S V^T``
    (``xi = T z``): then ``U = [I_r; 0]`` and ``U W_r U^T = diag(W_r, 0)`` has no data
    in it, so the program stays DPP (parameters ``A, B, B E E^T B^T, M, G`` of the
    rotated problem).  :meth:`point` maps ``X, R, Q`` back; the certificate is verified
    on the original problem like every other.  Same objective and normalization
    (``W_r`` in place of ``W``).
    """

    cold_first = True      # larger programs: cvxpy's DPP compilation costs more than a solve

    def __init__(self, n: int, m: int, r: int, pr: int, nominal: bool, gain_bound: bool):
        import cvxpy as cp
        self.cp = cp
        self.nominal = nominal
        self.n, self.r, self.pr = n, r, pr
        self.A = cp.Parameter((n, n), name='A')
        self.B = cp.Parameter((n, m), name='B')
        self.X = cp.Variable((n, n), symmetric=True, name='X')
        self.R = cp.Variable((m, n), name='R')
        self.t = cp.Variable(name='t')
        S = self.A @ self.X + self.B @ self.R
        top = S + S.T
        norm = cp.trace(self.X)
        Z = np.zeros
        cols: list[Any] = []        # blocks right of ``top`` in the first block row
        diag: list[Any] = []        # their diagonal blocks
        self.W: Any = None           # cvxpy Variable / Parameter when r > 0
        self.M: Any = None
        if r:
            self.W = cp.Variable((r, r), symmetric=True, name='W_r')
            self.M = cp.Parameter((n, r), name='M')
            top = top + (self.W if r == n else cp.bmat([[self.W, Z((r, n - r))],
                                                       [Z((n - r, r)), Z((n - r, n - r))]]))
            cols.append(self.X @ self.M)
            diag.append(-self.W)
            norm = norm + cp.trace(self.W)
        if nominal:
            self.eps, extra = None, []
        else:
            self.eps = cp.Variable(name='eps')
            self.BEBE = cp.Parameter((n, n), name='BEEB')
            top = top + self.eps * self.BEBE
            if pr:
                self.G = cp.Parameter((pr, n), name='G')
                cols.append(self.X @ self.G.T)
                diag.append(-self.eps * np.eye(pr))
            norm = norm + self.eps
            extra = [self.eps >= self.t]
        sizes = [c.shape[1] for c in cols]
        blocks = [[top] + cols]
        for i, c in enumerate(cols):
            blocks.append([c.T] + [diag[i] if j == i else Z((sizes[i], sizes[j]))
                                   for j in range(len(cols))])
        self._maximize_strictness(blocks, n + sum(sizes), norm, extra, n, m, gain_bound,
                                  lean=True)

    def set_data(self, problem: Problem, kappa: float | None = None) -> None:
        """Rotate ``problem`` (class docstring) and put its data into the parameters."""
        T, s, Vt, _ = _rank_split(problem.A_tau)
        r = self.r
        self.T = T
        self.A.value = T.T @ problem.A @ T
        self.B.value = T.T @ problem.B
        if self.r:
            M = (s[:r, None] * Vt[:r] @ T).T          # A_tau = T diag(s) V^T: T^T A_tau T
            self.M.value = M                          # = [M^T; 0]
        if not self.nominal:
            BE = self.B.value @ problem.E
            self.BEBE.value = BE @ BE.T
            if self.pr:
                _, sf, Vft, _ = _rank_split(problem.F @ T)
                self.G.value = sf[:self.pr, None] * Vft[:self.pr]
        if self.kappa2 is not None:
            self.kappa2.value = float(cast(float, kappa)) ** 2   # given with gain_bound

    def point(self, status: str, solve_time: float) -> tuple[Any, ...]:
        """``(status, t, X, Q, R, eps, solve_time)`` in the original coordinates."""
        t, X, R = self.t.value, self.X.value, self.R.value
        eps = None if self.eps is None else self.eps.value
        if X is None or R is None or t is None:
            return status, t, None, None, None, eps, solve_time
        X = _sym(X)
        try:
            Pz = np.linalg.inv(X)
            Qz = 0.5 * max(float(t), 0.0) * Pz @ Pz        # half the slack t P^2
            if self.r:
                Qz = Qz + self.M.value @ np.linalg.solve(_sym(self.W.value), self.M.value.T)
        except np.linalg.LinAlgError:
            return status, t, None, None, None, eps, solve_time
        T = self.T
        return (status, t, T @ X @ T.T, _sym(T @ Qz @ T.T), R @ T.T, eps, solve_time)


COMPACT_FROM_N = 8    # Theorem 1 uses _ReducedProgram for n >= this (smaller SDP)
#: set while :func:`_verified` falls back to the paper's form
_PAPER_FORM: contextvars.ContextVar[bool] = contextvars.ContextVar('paper_form', default=False)


def _program_for(problem: Problem, nominal: bool, gain_bound: bool) -> _Theorem1Program:
    """The Theorem 1 program for ``problem``.

    The paper's form (:func:`_program`) for ``n < COMPACT_FROM_N``, else the reduced one
    (same feasible set, cached per shape and ranks).
    """
    if problem.n < COMPACT_FROM_N or _PAPER_FORM.get():
        return _program(problem, nominal, gain_bound)
    key = (problem.n, problem.m) + _reduced_shape(problem) + (nominal, gain_bound)
    return cached_program(('theorem1-reduced',) + key, lambda: _ReducedProgram(*key))


# ---------------------------------------------------------------------------------------------
# Moderate gains by default, recovery from failed verification, trust warning.

MODERATE_FRACTION = 0.5   # unbounded synthesis: keep this fraction of the best margin t_max
TRUST_GAIN_NORM = 1e3     # ||K||_2 above this (or cond(P) above TRUST_COND_P): warn
TRUST_COND_P = 1e8
SECOND_SOLVER = 'SCS'


class UntrustedGainWarning(UserWarning):
    """A certified gain whose size a double-precision check cannot vouch for."""


class _MinNormProgram:
    """Stage 2 of unbounded synthesis: the smallest gain-norm bound at a given margin.

    Same variables and normalization as the unbounded ``_Theorem1Program``
    (``tr X + tr W + eps <= 1``), margin fixed to ``t_req`` (a parameter), and
    ``minimize s`` s.t. ``[[s I, R], [R^T, X]] >= 0``, i.e. ``R X^-1 R^T <= s I``:
    with ``X >= t_req I`` this bounds ``||K||_2 = ||R X^-1||_2 <= sqrt(s / t_req)``.
    """

    def __init__(self, base: _Theorem1Program):
        import cvxpy as cp
        self.cp = cp
        self.base = b = base
        self.t_req = cp.Parameter(nonneg=True, name='t_req')
        self.s = cp.Variable(name='s')
        m = b.R.shape[0]
        G = cp.bmat([[self.s * np.eye(m), b.R], [b.R.T, b.X]])
        cons = [c for c in b.problem.constraints] + [b.t >= self.t_req, 0.5 * (G + G.T) >> 0]
        self.problem = cp.Problem(cp.Minimize(self.s), cons)

    def solve(self, problem: Problem, solver: str, t_req: float) -> tuple[Any, ...]:
        """``(status, t, X, Q, R, eps, solve_time)`` (see :meth:`_Theorem1Program.point`)."""
        self.base.set_data(problem)
        self.t_req.value = float(t_req)
        out = solve(self.problem, solver, what='the minimum-norm stage for problem '
                    f'{problem.name!r}', ignore_dpp=self.base.first_solve())
        return self.base.point(out.status, out.solve_time)


def _min_norm_program(problem: Problem, nominal: bool) -> _MinNormProgram:
    """The stage-2 program for ``problem``'s shape (same form as :func:`_program_for`)."""
    n, m = problem.n, problem.m
    if n < COMPACT_FROM_N or _PAPER_FORM.get():
        shape = (n, m, problem.E.shape[1], problem.F.shape[0], nominal)
        return cached_program(('min-norm',) + shape, lambda: _MinNormProgram(
            _Theorem1Program(*shape, False)))
    key = (n, m) + _reduced_shape(problem) + (nominal,)
    return cached_program(('min-norm-reduced',) + key,
                          lambda: _MinNormProgram(_ReducedProgram(*key, False)))


def _min_norm_stage(problem: Problem, nominal: bool, solver: str, t_req: float,
                    verify_tol: float) -> SynthesisResult | None:
    """Stage 2 (see ``_MinNormProgram``); ``None`` if it gives no verified gain."""
    prog = _min_norm_program(problem, nominal)
    t0 = time.perf_counter()
    try:
        status, t, X, Q, R, eps, solve_time = prog.solve(problem, solver, t_req)
    except SolverFailure:
        return None
    if status not in OK_STATUSES or X is None or t is None or Q is None:
        return None
    try:
        P = np.linalg.inv(_sym(X))
    except np.linalg.LinAlgError:
        return None
    K = R @ P
    cert = _certificate(problem, K, P, Q, None if nominal else float(eps), verify_tol)
    if not cert.verification.ok:
        return None
    return SynthesisResult(K=K, certificate=cert, margin_required=t_req,
                           margin_achieved=float(t), status=status,
                           solver=solver, solve_time=solve_time,
                           wall_time=time.perf_counter() - t0, nominal=nominal)


def _balanced(problem: Problem) -> tuple[Problem, np.ndarray]:
    """Diagonal similarity ``xi = T z`` balancing ``|A| + |A_tau|`` (LAPACK gebal)."""
    import scipy.linalg as sla
    M = np.abs(problem.A) + np.abs(problem.A_tau) + np.abs(problem.B) @ np.ones(
        (problem.m, problem.n)) / max(problem.m, 1)
    _, (scale, _) = sla.matrix_balance(M, permute=False, separate=True)
    T = np.diag(scale)
    Ti = np.diag(1.0 / scale)
    return problem.replace(A=Ti @ problem.A @ T, B=Ti @ problem.B, A_tau=Ti @ problem.A_tau @ T,
                           F=problem.F @ T), T


def _from_balanced(problem: Problem, res: SynthesisResult, T: np.ndarray,
                   verify_tol: float) -> SynthesisResult | None:
    """Map a gain of the balanced problem back (``K = K_z T^-1``) and verify it there."""
    Ti = np.linalg.inv(T)
    c = res.certificate
    K = c.K @ Ti
    P = _sym(Ti.T @ c.P @ Ti)
    Q = _sym(Ti.T @ c.Q @ Ti)
    cert = _certificate(problem, K, P, Q, c.eps, verify_tol)
    return None if not cert.verification.ok else replace(res, K=K, certificate=cert)


def _verified(problem: Problem, **kw: Any) -> SynthesisResult:
    """:func:`_verified_chain`; for ``n >= COMPACT_FROM_N`` the paper's form as a last resort.

    When no point of the reduced program verifies, the whole chain is run again with the
    paper's form (``_Theorem1Program``), whose verdict (a verified gain,
    ``InfeasibleError`` at the edge of feasibility, ``CertificateError``) is the answer:
    the reduction never makes the outcome worse than the paper's form, only faster when
    it verifies.
    """
    try:
        return _verified_chain(problem, **kw)
    except CertificateError as exc:
        if problem.n < COMPACT_FROM_N or _PAPER_FORM.get():
            raise
        reduced = str(exc)
    token = _PAPER_FORM.set(True)
    try:
        res = _verified_chain(problem, **kw)
    except CertificateError as exc:
        raise CertificateError(f'{exc} | reduced LMI first: {reduced}') from None
    finally:
        _PAPER_FORM.reset(token)
    res.extra['recovered_by'] = 'paper-form LMI (the reduced one gave no verified point)'
    return res


def _verified_chain(problem: Problem, **kw: Any) -> SynthesisResult:
    """Synthesize once; if the point fails verification, retry before giving up.

    The retries are the balanced problem, a 100x higher margin, then the second solver.
    """
    try:
        return _synthesize_once(problem, **kw)
    except CertificateError as first:
        tried = [f'{kw.get("solver") or "default solver"}: {first}']
        t_first = getattr(first, 'margin_achieved', None)
    verify_tol = kw.get('verify_tol', 1e-9)
    margin = float(problem.options.get('margin', DEFAULT_MARGIN) if kw.get('margin') is None
                   else kw['margin'])
    solver = str(problem.options.get('solver', DEFAULT_SOLVER) if kw.get('solver') is None
                 else kw['solver'])
    if kw.get('gain_bound') is None and t_first is not None:
        # the most strictly feasible point is often badly scaled (tiny X, huge P and K):
        # the minimum-norm point at half its margin usually verifies
        req = max(margin, MODERATE_FRACTION * t_first)
        res = _min_norm_stage(problem, kw.get('nominal', False), solver, req, verify_tol)
        if res is not None:
            return replace(res, margin_required=margin, extra=dict(
                recovered_by='minimum-norm stage', t_max=t_first, rule='moderate',
                fraction=MODERATE_FRACTION))
        tried.append(f'minimum-norm stage at t >= {req:.3g}: no verified point')
    attempts = [('balanced problem', dict(kw), True),
                ('margin x100', dict(kw, margin=100 * margin), False),
                (f'solver {SECOND_SOLVER}', dict(kw, solver=SECOND_SOLVER), False),
                (f'solver {SECOND_SOLVER}, balanced', dict(kw, solver=SECOND_SOLVER), True)]
    for what, args, balance in attempts:
        try:
            if balance:
                bal, T = _balanced(problem)
                res = _from_balanced(problem, _synthesize_once(bal, **args), T, verify_tol)
                if res is None:
                    tried.append(f'{what}: the mapped-back certificate fails verification')
                    continue
            else:
                res = _synthesize_once(problem, **args)
            res.extra['recovered_by'] = what
            return res
        except InfeasibleError as exc:
            tried.append(f'{what}: infeasible ({exc})')
        except LmiError as exc:
            tried.append(f'{what}: {exc}')
    if t_first is not None and t_first < 100 * margin and any(
            'infeasible' in x for x in tried):
        raise InfeasibleError(
            f'Theorem 1 for problem {problem.name!r} is feasible only at the edge: the best '
            f'margin t = {t_first:.3g} is below 100 x the required {margin:g}, and no point '
            'found passes the double-precision verification (attempts: '
            + ' | '.join(tried) + '). Treat it as infeasible: try a smaller A_tau or F, '
            'the nominal design, or the delay-dependent design.')
    raise CertificateError(f'no verified gain for problem {problem.name!r}; attempts: '
                           + ' | '.join(tried))


def gain_trust_message(problem: Problem, K: np.ndarray, P: np.ndarray) -> str | None:
    """Why a double-precision check cannot vouch for this certified gain, or ``None``.

    Rule: ``||K||_2 > 1e3`` or ``cond(P) > 1e8``.  The check is an eigenvalue test of
    ``V`` (module docstring) whose entries are ``~ ||P|| ||B|| ||K||``; LAPACK's
    eigenvalues carry an absolute error ``~ 1e-16 ||V||``, while the slack that proves
    ``V < 0`` lives on directions where ``P`` is small (``~ ||P|| / cond(P)``).  With
    ``cond(P) > 1e8`` or a gain that large the proof rests on digits that round-off
    reaches - and no actuator applies such a gain anyway.

    Parameters
    ----------
    problem : Problem
        For the message (its name).
    K : numpy.ndarray, shape (m, n)
        The gain.
    P : numpy.ndarray, shape (n, n)
        The certificate's ``P``.

    Returns
    -------
    str or None
        The warning, or ``None`` when the gain is within the rule.
    """
    norm = float(np.linalg.norm(K, 2))
    cond = float(np.linalg.cond(P))
    if norm <= TRUST_GAIN_NORM and cond <= TRUST_COND_P:
        return None
    return (f'gain for {problem.name!r} has ||K||_2 = {norm:.3g} and cond(P) = {cond:.3g}; '
            f'beyond ||K||_2 <= {TRUST_GAIN_NORM:g} and cond(P) <= {TRUST_COND_P:g} a '
            'double-precision certificate check is not trustworthy (round-off ~1e-16 ||V|| '
            'against a slack ~||P|| / cond(P)). Give a gain bound (--gain-bound / '
            'options.gain_bound).')


def decoupled_blocks(problem: Problem) -> list[tuple[np.ndarray, np.ndarray, np.ndarray,
                                                     np.ndarray]]:
    """Independent sub-problems of Theorem 1: index sets ``(states, inputs, q, p)``.

    States, inputs, the columns of ``E`` (``q``) and the rows of ``F`` (``p``) are
    nodes of a graph; a nonzero ``A[i, j]``, ``A_tau[i, j]``, ``B[i, k]``, ``E[k, l]``
    or ``F[r, j]`` joins two of them.  Each connected component with at least one of
    each kind is a block; one block (or a component without inputs or perturbation)
    means no decoupling and returns ``[]``.

    Parameters
    ----------
    problem : Problem
        The data ``A, A_tau, B, E, F`` (their sparsity pattern).

    Returns
    -------
    list of tuple of numpy.ndarray
        ``(states, inputs, q, p)`` index arrays per block; ``[]``: no decoupling.
    """
    n, m = problem.n, problem.m
    q, p = problem.E.shape[1], problem.F.shape[0]
    parent = list(range(n + m + q + p))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def join(rows: np.ndarray, cols: np.ndarray) -> None:
        for a, b in zip(rows.tolist(), cols.tolist()):
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[ra] = rb

    for M in (problem.A, problem.A_tau):
        i, j = np.nonzero(M)
        join(i, j)
    i, k = np.nonzero(problem.B)
    join(i, n + k)
    k, l_ = np.nonzero(problem.E)
    join(n + k, n + m + l_)
    r, j = np.nonzero(problem.F)
    join(n + m + q + r, j)
    comps: dict[int, list[int]] = {}
    for a in range(n + m + q + p):
        comps.setdefault(find(a), []).append(a)
    if len(comps) < 2:
        return []
    blocks = []
    for nodes in comps.values():
        idx = np.array(nodes)
        st = idx[idx < n]
        inp = idx[(idx >= n) & (idx < n + m)] - n
        qq = idx[(idx >= n + m) & (idx < n + m + q)] - n - m
        pp = idx[idx >= n + m + q] - n - m - q
        if min(st.size, inp.size, qq.size, pp.size) == 0:
            return []
        blocks.append((st, inp, qq, pp))
    return blocks


def _synthesize_blocks(problem: Problem, blocks: Sequence[tuple[np.ndarray, ...]], *,
                       nominal: bool, verify_tol: float, **kw: Any) -> SynthesisResult | None:
    """Solve each decoupled block, assemble, verify the whole; ``None`` if that fails.

    With block-diagonal data and a common ``eps`` the matrix ``V`` of the module
    docstring is a permutation of ``diag(V_i)``.  Scaling a block's ``(P_i, Q_i)`` by
    ``c`` is equivalent to replacing its ``eps_i`` by ``c eps_i`` (divide the Schur
    complement of ``V_i`` by ``c``), so ``(eps_i P_i, eps_i Q_i)`` with ``eps = 1``
    certifies every block at once.  ``||K||_2 = max ||K_i||_2``.
    """
    n, m = problem.n, problem.m
    K = np.zeros((m, n))
    P = np.zeros((n, n))
    Q = np.zeros((n, n))
    parts: list[SynthesisResult] = []
    for st, inp, qq, pp in blocks:
        sub = problem.replace(A=problem.A[np.ix_(st, st)], B=problem.B[np.ix_(st, inp)],
                              A_tau=problem.A_tau[np.ix_(st, st)],
                              E=problem.E[np.ix_(inp, qq)], F=problem.F[np.ix_(pp, st)],
                              perturbations={}, name=f'{problem.name}[block {len(parts)}]')
        r = synthesize(sub, nominal=nominal, verify_tol=verify_tol, **kw)
        c = 1.0 if nominal else float(cast(float, r.eps))    # not nominal: eps is set
        K[np.ix_(inp, st)] = r.K
        P[np.ix_(st, st)] = c * r.P
        Q[np.ix_(st, st)] = c * r.Q
        parts.append(r)
    cert = _certificate(problem, K, P, Q, None if nominal else 1.0, verify_tol)
    if not cert.verification.ok:
        return None
    first = parts[0]
    extra = dict(first.extra, blocks=[int(b[0].size) for b in blocks])
    for key in ('t_max', 'stage1_norm'):
        if all(key in r.extra for r in parts):
            extra[key] = (min if key == 't_max' else max)(r.extra[key] for r in parts)
    warn = [r.extra['warning'] for r in parts if 'warning' in r.extra]
    if warn:
        extra['warning'] = warn[0]
    else:
        extra.pop('warning', None)
    return SynthesisResult(K=K, certificate=cert, margin_required=first.margin_required,
                           margin_achieved=min(r.margin_achieved for r in parts),
                           status=first.status, solver=first.solver,
                           solve_time=sum(r.solve_time for r in parts), wall_time=0.0,
                           nominal=nominal, extra=extra)


def synthesize(problem: Problem, *, nominal: bool = False, margin: float | None = None,
               solver: str | None = None, gain_bound: float | None = None,
               verify_tol: float = 1e-9, moderate: bool = True,
               decouple: bool = True) -> SynthesisResult:
    """Solve Theorem 1 (or its nominal form) and return a verified gain.

    Parameters
    ----------
    problem : Problem
        The data ``A, B, A_tau, E, F`` (``tau`` does not enter: the condition is
        delay-independent).
    nominal : bool
        Drop the ``E, F`` terms (the paper's "normal state feedback").
    margin : float
        Required strictness ``t`` (normalized units); default ``problem.options['margin']``
        or 1e-6.
    solver : str
        cvxpy solver name; default ``problem.options['solver']`` or ``'CLARABEL'``.
    gain_bound : float, optional
        Also impose ``||K||_2 <= gain_bound`` (see ``_Theorem1Program``).
    moderate : bool
        Without ``gain_bound``: two stages (default).  Stage 1 finds the largest margin
        ``t_max`` (the most strictly feasible point, whose gain can be huge: norms of
        1e6-1e7 on random problems); stage 2 keeps ``t >= max(margin,
        0.5 t_max)`` and minimizes the gain-norm bound ``s`` with ``R X^-1 R^T <= s I``
        (``_MinNormProgram``).  ``extra`` records ``rule``, ``t_max`` and the
        stage-1 norm.  ``False``: stage 1 only (the behaviour before).
    verify_tol : float
        Relative tolerance of :func:`verify_certificate`.
    decouple : bool
        If the data split into independent blocks (:func:`decoupled_blocks`, e.g. several
        robots), solve each block and assemble a block-diagonal certificate (see
        ``_synthesize_blocks``), verified on the whole problem; on failure the whole
        problem is solved as one.  ``extra['blocks']`` lists the block sizes.

    Returns
    -------
    SynthesisResult
        Verified.  If ``||K||_2 > 1e3`` or ``cond(P) > 1e8`` an
        :class:`UntrustedGainWarning` is issued and ``extra['warning']`` holds why
        (:func:`gain_trust_message`).

    Raises
    ------
    InfeasibleError
        No point with ``t >= margin`` exists; nothing is returned.
    SolverFailure
        The solver is missing or returned no solution.
    CertificateError
        The solver's point failed :func:`verify_certificate`, and so did the
        retries: the balanced problem (diagonal similarity), a 100x higher margin,
        the second solver (SCS), SCS on the balanced problem.
    """
    if gain_bound is not None and not gain_bound > 0:
        raise ValueError(f'gain_bound must be > 0, got {gain_bound!r}')
    t0 = time.perf_counter()
    blocks = decoupled_blocks(problem) if decouple else []
    if blocks:
        with warnings.catch_warnings():        # warned once below for the whole gain
            warnings.simplefilter('ignore', UntrustedGainWarning)
            res = _synthesize_blocks(problem, blocks, nominal=nominal, verify_tol=verify_tol,
                                     margin=margin, solver=solver, gain_bound=gain_bound,
                                     moderate=moderate)
        if res is not None:
            if 'warning' in res.extra:
                warnings.warn(res.extra['warning'], UntrustedGainWarning, stacklevel=2)
            return replace(res, wall_time=time.perf_counter() - t0)
    kw = dict(nominal=nominal, margin=margin, solver=solver, gain_bound=gain_bound,
              verify_tol=verify_tol)
    res = _verified(problem, **kw)
    if gain_bound is None and moderate and res.extra.get('rule') != 'moderate':
        t_max = res.margin_achieved
        req = max(float(res.margin_required), MODERATE_FRACTION * t_max)
        stage2 = _min_norm_stage(problem, nominal, res.solver, req, verify_tol)
        norm1 = float(np.linalg.norm(res.K, 2))
        if stage2 is not None and np.linalg.norm(stage2.K, 2) <= norm1:
            extra = dict(res.extra, rule='moderate', t_max=t_max, stage1_norm=norm1,
                         fraction=MODERATE_FRACTION)
            res = replace(stage2, margin_required=res.margin_required,
                          solve_time=res.solve_time + stage2.solve_time, extra=extra)
        else:
            res.extra.update(rule='max-margin (the minimum-norm stage gave no better '
                             'verified gain)', t_max=t_max, stage1_norm=norm1)
    elif gain_bound is None:
        res.extra.setdefault('rule', 'max-margin')
    msg = gain_trust_message(problem, res.K, res.P)
    if msg is not None:
        res.extra['warning'] = msg
        warnings.warn(msg, UntrustedGainWarning, stacklevel=2)
    return replace(res, wall_time=time.perf_counter() - t0)


# ---------------------------------------------------------------------------------------------
# Certify a given K.

class _CertifyProgram:
    """The fixed-gain certification LMI of :func:`certify_gain`, compiled once per shape.

    ``A + B K``, ``A_tau``, ``F^T F`` and ``B E`` are parameters (cvxpy DPP): a re-solve
    for another gain, problem or perturbation scale skips the compilation.
    """

    def __init__(self, n: int, q: int, p: int, nominal: bool):
        import cvxpy as cp
        self.nominal = nominal
        self.A0 = cp.Parameter((n, n), name='A_BK')
        self.Ad = cp.Parameter((n, n), name='A_tau')
        self.P = cp.Variable((n, n), symmetric=True, name='P')
        self.Q = cp.Variable((n, n), symmetric=True, name='Q')
        self.t = cp.Variable(name='t')
        P, Q, t = self.P, self.Q, self.t
        top = P @ self.A0 + self.A0.T @ P + Q
        PAd = P @ self.Ad
        self.d: Any = None
        if nominal:
            V = cp.bmat([[top, PAd], [PAd.T, -Q]])
            cons, norm = [], cp.trace(P) + cp.trace(Q)
        else:
            self.FtF = cp.Parameter((n, n), name='FtF')
            self.BE = cp.Parameter((n, q), name='BE')
            self.d = d = cp.Variable(name='d')
            PBE = P @ self.BE
            V = cp.bmat([[top + d * self.FtF, PAd, PBE],
                         [PAd.T, -Q, np.zeros((n, q))],
                         [PBE.T, np.zeros((q, n)), -d * np.eye(q)]])
            cons, norm = [d >= t], cp.trace(P) + cp.trace(Q) + d
        V = 0.5 * (V + V.T)
        cons += [V << -t * np.eye(V.shape[0]), P >> t * np.eye(n), Q >> t * np.eye(n),
                 norm <= 1]
        self.problem = cp.Problem(cp.Maximize(t), cons)

    def solve(self, problem: Problem, K: np.ndarray, solver: str) -> str:
        """Solve for ``problem`` and ``K``; the status (values in ``t``, ``P``, ``Q``, ``d``)."""
        self.A0.value = problem.A + problem.B @ K
        self.Ad.value = problem.A_tau
        if not self.nominal:
            self.FtF.value = problem.F.T @ problem.F
            self.BE.value = problem.B @ problem.E
        return solve(self.problem, solver, what='the certification LMI for K').status


def certify_gain(problem: Problem, K: Any, *, nominal: bool = False,
                 margin: float | None = None,
                 solver: str | None = None, verify_tol: float = 1e-9) -> CertifyResult:
    """Decide whether Theorem 1's condition holds for the fixed gain ``K``.

    Solves ``maximize t`` s.t. ``V(P, Q, d) <= -t I``, ``P, Q >= t I``, ``d >= t``,
    ``tr P + tr Q + d <= 1`` where ``d = 1/eps``; certified iff ``t >= margin`` and the
    resulting certificate passes :func:`verify_certificate`.

    Parameters
    ----------
    problem : Problem
        The data ``A, B, A_tau, E, F``.
    K : array_like, shape (m, n)
        The gain.
    nominal : bool, optional
        Certify ``D = 0`` only.
    margin : float, optional
        Required strictness; default ``problem.options['margin']`` or 1e-6.
    solver : str, optional
        cvxpy solver; default ``problem.options['solver']`` or ``'CLARABEL'``.
    verify_tol : float, optional
        Relative tolerance of :func:`verify_certificate`.

    Returns
    -------
    CertifyResult
    """
    margin = float(problem.options.get('margin', DEFAULT_MARGIN) if margin is None else margin)
    solver = str(problem.options.get('solver', DEFAULT_SOLVER) if solver is None else solver)
    K = problem.gain(K)
    key = ('theorem1_certify', problem.n, problem.E.shape[1], problem.F.shape[0], nominal)
    prog = cached_program(key, lambda: _CertifyProgram(*key[1:]))
    status = prog.solve(problem, K, solver)
    t, P, Q = prog.t.value, prog.P.value, prog.Q.value
    if status not in OK_STATUSES or t is None or P is None or Q is None:
        return CertifyResult(False, float('-inf'), None, status)
    tv = float(t)
    if tv < margin:
        return CertifyResult(False, tv, None, status)
    eps = None if prog.d is None else 1.0 / float(prog.d.value)
    cert = _certificate(problem, K, _sym(np.array(P)), _sym(np.array(Q)), eps, verify_tol)
    return CertifyResult(cert.verification.ok, tv, cert, status)


def certified_perturbation_scale(problem: Problem, K: Any, *, upper: float = 100.0,
                                 rel_tol: float = 1e-3, solver: str | None = None) -> float:
    """Largest ``s`` such that :func:`certify_gain` certifies ``K`` with ``F -> s F``.

    Bisection: certification is monotone in ``s`` (a certificate for ``s`` also
    certifies every smaller scale).  Returns 0.0 if even the nominal condition fails
    and ``upper`` if ``upper`` itself is certified.  A solver failure at a trial
    scale (it happens for extreme scales) counts as "not certified" there.

    Parameters
    ----------
    problem : Problem
        The data (``F`` is scaled).
    K : array_like, shape (m, n)
        The gain.
    upper : float, optional
        Largest scale tried.
    rel_tol : float, optional
        Relative width of the final bracket.
    solver : str, optional
        cvxpy solver (default as in :func:`certify_gain`).

    Returns
    -------
    float
        The largest certified scale (a lower bound within ``rel_tol``).
    """
    from .search import largest_feasible

    def trial(s: float) -> CertifyResult | None:
        try:
            res = certify_gain(problem.replace(F=s * problem.F), K, solver=solver)
        except SolverFailure:
            return None
        return res if res.certified else None

    if not certify_gain(problem, K, nominal=True, solver=solver).certified:
        return 0.0
    return largest_feasible(trial, 0.0, 1.0, rel_tol=rel_tol, hi_limit=upper)[0]
