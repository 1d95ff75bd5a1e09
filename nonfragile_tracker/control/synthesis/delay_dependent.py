r"""Delay-dependent non-fragile state feedback: descriptor method with Jensen's inequality.

Closed loop (constant delay ``h``, time-varying gain perturbation)::

    x'(t) = A_c(t) x(t) + A_d x(t - h),   A_c(t) = A + B (K + E D(t) F),  D^T D <= I,

with ``A_d = problem.A_tau``.  Unlike Theorem 1 (:mod:`.lmi`) the condition depends on
``h``, so it can certify loops that Theorem 1 cannot; every certificate is verified in
numpy (:func:`verify_delay_dependent`).

See doc/theory.md, section "Delay-dependent design" (#delay-dependent-design): the
sources, the functional, the derivation, the ``eps`` and ``h_max`` searches, the caveats.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Sequence, cast

import numpy as np

from .errors import CertificateError, InfeasibleError, SolverFailure
from .certificate import (CertifiedGain, Verification, eigen_figures, from_certificate,
                          passes, retry_advice)
from .problem import Problem
from .search import eps_search
from .sdp import (DEFAULT_MARGIN, DEFAULT_SOLVER, INFEASIBLE_STATUSES, OK_STATUSES,
                  DescriptorParameters, cached_program, solve_for_point)
from .sdp import sym as _sym

__all__ = ['DEFAULT_EPS_GRID', 'DescriptorSolution',
           'DelayDependentVerification', 'DelayDependentCertificate',
           'DelayDependentResult', 'descriptor_verification_matrix', 'verify_delay_dependent',
           'synthesize_delay_dependent', 'max_certified_delay']

DEFAULT_EPS_GRID: tuple[float, ...] = tuple(float(e) for e in np.logspace(-3, 2, 21))
DEFAULT_REFINE = 8
_OK = OK_STATUSES
_INFEASIBLE = INFEASIBLE_STATUSES


# ---------------------------------------------------------------------------------------------
# records

@dataclass(frozen=True)
class DelayDependentVerification(Verification):
    """Outcome of :func:`verify_delay_dependent` (:class:`.certificate.Verification`).

    Eigenvalue checks in original coordinates.

    Besides ``ok`` and the keywords ``tolerance`` and ``scale`` of the base:

    Parameters
    ----------
    max_eig_Psi : float
        Largest eigenvalue of ``Psi`` (must be ``< -tolerance * scale``).
    min_eig_P1, min_eig_S, min_eig_R : float
        Smallest eigenvalues of ``P1``, ``S``, ``R`` (must be > 0).
    lam : float or None
        Petersen scalar (must be > 0; ``None``: nominal).
    """

    max_eig_Psi: float
    min_eig_P1: float
    min_eig_S: float
    min_eig_R: float
    lam: float | None

    MATRIX = 'Psi'
    WORST = 'max_eig_Psi'
    POSITIVE = (('min_eig_P1', 'P1'), ('min_eig_S', 'S'), ('min_eig_R', 'R'))


@dataclass(frozen=True)
class DelayDependentCertificate:
    """Lyapunov-Krasovskii certificate (original coordinates) for ``K`` at delay ``h``.

    ``P3 = eps P2`` for certificates produced by the synthesis; the verification
    accepts any ``P2, P3``.  ``lam is None`` means the nominal (D = 0) condition.
    """

    K: np.ndarray
    h: float
    eps: float
    P1: np.ndarray
    P2: np.ndarray
    P3: np.ndarray
    S: np.ndarray
    R: np.ndarray
    lam: float | None
    verification: DelayDependentVerification


@dataclass(frozen=True, kw_only=True)
class DelayDependentResult(CertifiedGain):
    """A delay-dependent gain with its verified certificate and solver facts.

    The fields of :class:`.certificate.CertifiedGain` (keywords; ``margin_achieved`` is the
    strictness at the chosen ``eps``, ``solve_time`` summed over the ``eps`` search) and:

    Parameters
    ----------
    h : float
        The certified delay (s).
    eps : float
        The tuning scalar used (``P3 = eps P2``).
    gain_bound : float or None
        The ``||K||_2`` bound imposed.
    eps_scan : tuple of (float, float)
        ``(eps, t)`` of every solve (``t = -inf``: no point).
    """

    h: float
    eps: float
    certificate: DelayDependentCertificate
    gain_bound: float | None
    eps_scan: tuple[tuple[float, float], ...] = ()

    P1 = from_certificate('P1', 'Matrix ``P1`` of the certificate (positive definite).')
    S = from_certificate('S', 'Matrix ``S`` of the certificate (positive definite).')
    R = from_certificate('R', 'Matrix ``R`` of the certificate (positive definite).')
    lam = from_certificate('lam', 'Petersen scalar of the certificate (None: the nominal '
                           'condition).')
    verification = from_certificate('verification', 'The independent check of the '
                                    'certificate.')


@dataclass(frozen=True)
class DescriptorSolution:
    """One solve of the descriptor SDP at a fixed ``eps`` (solver coordinates).

    ``X`` etc. are ``None`` unless the status is optimal; ``t`` is the strictness
    (``None`` if the solver gave no value).
    """

    status: str
    t: float | None
    solve_time: float
    eps: float
    X: np.ndarray | None = None
    Y: np.ndarray | None = None
    Pb: np.ndarray | None = None
    Sb: np.ndarray | None = None
    Rb: np.ndarray | None = None
    lam: float | None = None

    @property
    def strictness(self) -> float:
        """``t`` of a usable point, ``-inf`` otherwise."""
        if self.status not in _OK or self.t is None or self.X is None:
            return -math.inf
        return float(self.t)


# ---------------------------------------------------------------------------------------------
# independent verification (numpy only)

def descriptor_verification_matrix(A: np.ndarray, B: np.ndarray, A_tau: np.ndarray,
                                   E: np.ndarray, F: np.ndarray, K: np.ndarray, h: float,
                                   P1: np.ndarray, P2: np.ndarray, P3: np.ndarray,
                                   S: np.ndarray, R: np.ndarray, lam: float | None
                                   ) -> np.ndarray:
    """``Psi`` of the delay-dependent condition (doc/theory.md, step 5), symmetric.

    Parameters
    ----------
    A, B, A_tau, E, F, K : numpy.ndarray
        Plant, perturbation structure and gain, as in :func:`.lmi.verification_matrix`.
    h : float
        The delay (s).
    P1, P2, P3, S, R : numpy.ndarray, shape (n, n)
        The certificate's matrices.
    lam : float or None
        Petersen scalar; ``None``: ``Phi_0`` alone (nominal, ``3n x 3n``).

    Returns
    -------
    numpy.ndarray
        ``(3n + q + p)`` square, or ``3n`` square for the nominal form.
    """
    n = A.shape[0]
    Ac = A + B @ K
    phi11 = P2.T @ Ac + Ac.T @ P2 + S - R
    phi12 = P1 - P2.T + Ac.T @ P3
    phi13 = P2.T @ A_tau + R
    phi22 = -(P3 + P3.T) + h * h * R
    phi23 = P3.T @ A_tau
    phi33 = -S - R
    phi = _sym(np.block([[phi11, phi12, phi13],
                         [phi12.T, phi22, phi23],
                         [phi13.T, phi23.T, phi33]]))
    if lam is None:
        return phi
    q, p = E.shape[1], F.shape[0]
    BE = B @ E
    U = np.vstack([P2.T @ BE, P3.T @ BE, np.zeros((n, q))])
    V = np.hstack([F, np.zeros((p, 2 * n))])
    psi = np.block([
        [phi, lam * U, V.T],
        [lam * U.T, -lam * np.eye(q), np.zeros((q, p))],
        [V, np.zeros((p, q)), -lam * np.eye(p)],
    ])
    return _sym(psi)


def verify_delay_dependent(problem: Problem, K: Any, h: float,
                           certificate: DelayDependentCertificate, *, tol: float = 1e-9
                           ) -> DelayDependentVerification:
    """Check the delay-dependent condition from ``(K, h, P1, P2, P3, S, R, lam)`` with numpy.

    Uses only ``K``, ``h`` (the arguments) and the matrices/scalar of ``certificate``
    (its own ``K``, ``h``, ``eps`` and ``verification`` are ignored).  Passes iff
    ``P1, S, R > 0``, ``lam > 0`` (unless nominal) and
    ``max eig(Psi) < -tol * ||Psi||``.  Never raises for a failed check: see ``ok``.

    Parameters
    ----------
    problem, K, tol
        As in :func:`.lmi.verify_certificate` (``tol``: the slack demanded of ``Psi``).
    h : float
        The delay (s, finite, >= 0).
    certificate : DelayDependentCertificate
        The matrices ``P1, P2, P3, S, R`` and ``lam``.

    Returns
    -------
    DelayDependentVerification
    """
    K = problem.gain(K)
    h = float(h)
    if not (math.isfinite(h) and h >= 0):
        raise ValueError(f'h must be a finite delay >= 0, got {h!r}')
    c = certificate
    return _verify(problem, K, h, c.P1, c.P2, c.P3, c.S, c.R, c.lam, tol)


def _verify(problem: Problem, K: np.ndarray, h: float, P1: Any, P2: Any, P3: Any, S: Any,
            R: Any, lam: float | None, tol: float) -> DelayDependentVerification:
    """:func:`verify_delay_dependent` on the matrices themselves (``K``, ``h`` checked)."""
    P1, S, R = (_sym(np.asarray(M, float)) for M in (P1, S, R))
    P2, P3 = np.asarray(P2, float), np.asarray(P3, float)
    lam = None if lam is None else float(lam)
    Psi = descriptor_verification_matrix(problem.A, problem.B, problem.A_tau, problem.E,
                                         problem.F, K, h, P1, P2, P3, S, R, lam)
    top, scale, mins = eigen_figures(Psi, (P1, S, R))
    return DelayDependentVerification(passes(top, scale, mins, lam, tol), top, mins[0],
                                      mins[1], mins[2], lam, tolerance=tol, scale=scale)


# ---------------------------------------------------------------------------------------------
# the SDP (built once per shape, re-solved with new data through DPP parameters)

class _DescriptorProgram(DescriptorParameters):
    def __init__(self, n: int, m: int, q: int, p: int, nominal: bool, gain_bound: bool):
        import cvxpy as cp
        self.cp = cp
        self.nominal = nominal
        par = cp.Parameter
        self.A, self.B, self.Ad = par((n, n)), par((n, m)), par((n, n))
        self.eA, self.eB, self.eAd = par((n, n)), par((n, m)), par((n, n))   # eps-scaled
        self.eps, self.h2 = par(nonneg=True), par(nonneg=True)
        self.X = cp.Variable((n, n), name='X')
        self.Y = cp.Variable((m, n), name='Y')
        self.Pb = cp.Variable((n, n), symmetric=True, name='Pb')
        self.Sb = cp.Variable((n, n), symmetric=True, name='Sb')
        self.Rb = cp.Variable((n, n), symmetric=True, name='Rb')
        self.t = cp.Variable(name='t')
        X, Y, Pb, Sb, Rb = self.X, self.Y, self.Pb, self.Sb, self.Rb
        G = self.A @ X + self.B @ Y
        eG = self.eA @ X + self.eB @ Y                  # eps G, written DPP-compliant
        b11 = G + G.T + Sb - Rb
        b12 = Pb - X + eG.T
        b13 = self.Ad @ X + Rb
        b22 = -self.eps * (X + X.T) + self.h2 * Rb
        b23 = self.eAd @ X
        b33 = -Sb - Rb
        Z = np.zeros
        if nominal:
            blocks = [[b11, b12, b13], [b12.T, b22, b23], [b13.T, b23.T, b33]]
            size = 3 * n
            self.lam = None
            extra = []
            norm = cp.trace(Pb) + cp.trace(Sb) + cp.trace(Rb) + cp.trace(X)
        else:
            self.BE, self.eBE, self.F = par((n, q)), par((n, q)), par((p, n))
            self.lam = lam = cp.Variable(name='lam')
            c1, c2 = lam * self.BE, lam * self.eBE
            XF = X.T @ self.F.T
            blocks = [
                [b11, b12, b13, c1, XF],
                [b12.T, b22, b23, c2, Z((n, p))],
                [b13.T, b23.T, b33, Z((n, q)), Z((n, p))],
                [c1.T, c2.T, Z((q, n)), -lam * np.eye(q), Z((q, p))],
                [XF.T, Z((p, n)), Z((p, n)), Z((p, q)), -lam * np.eye(p)],
            ]
            size = 3 * n + q + p
            extra = [lam >= self.t]
            norm = cp.trace(Pb) + cp.trace(Sb) + cp.trace(Rb) + cp.trace(X) + lam
        L = cp.bmat(blocks)
        L = 0.5 * (L + L.T)
        I = np.eye(n)
        cons = [L << -self.t * np.eye(size), Pb >> self.t * I, Sb >> self.t * I,
                Rb >> self.t * I] + extra
        if gain_bound:
            # ||K||_2 <= kappa with K = Y X^-1, X not symmetric: see the module docstring.
            cons += self.gain_bound_constraints(X, Y, self.t)
        else:
            cons += [norm <= 1]
        self.problem = cp.Problem(cp.Maximize(self.t), cons)

    def set_data(self, problem: Problem, kappa: float | None) -> None:
        """Put ``problem``'s data (and the gain bound ``kappa``) into the parameters."""
        self.set_problem(problem, kappa)

    def solve(self, problem: Problem, h: float, eps: float, solver: str) -> DescriptorSolution:
        """Solve at delay ``h`` and tuning scalar ``eps`` (after :meth:`set_data`)."""
        self.set_eps(problem, eps)
        self.h2.value = h * h
        # 'optimal_inaccurate' is reported in the status; the point is verified anyway
        out, t, usable = solve_for_point(self.problem, solver, 'the descriptor LMI', self.t,
                                         self.X)
        if usable:
            return DescriptorSolution(
                status=out.status, t=t, solve_time=out.solve_time, eps=eps,
                X=np.array(self.X.value), Y=np.array(self.Y.value),
                Pb=np.array(self.Pb.value), Sb=np.array(self.Sb.value),
                Rb=np.array(self.Rb.value),
                lam=None if self.lam is None else float(cast(np.ndarray, self.lam.value)))
        return DescriptorSolution(status=out.status, t=t, solve_time=out.solve_time, eps=eps)


def _program(problem: Problem, nominal: bool, gain_bound: bool) -> _DescriptorProgram:
    shape = (problem.n, problem.m, problem.E.shape[1], problem.F.shape[0], nominal, gain_bound)
    return cached_program(('descriptor',) + shape, lambda: _DescriptorProgram(*shape))


def _t_of(sol: DescriptorSolution) -> float:
    return sol.strictness


def _certificate(problem: Problem, h: float, sol: DescriptorSolution, verify_tol: float
                 ) -> DelayDependentCertificate:
    """Back transformation of a solver point to original coordinates, then verification.

    ``sol`` is a usable point (``strictness > -inf``: ``X, Y, Pb, Sb, Rb`` are set).
    """
    X, Y, Pb, Sb, Rb = sol.X, sol.Y, sol.Pb, sol.Sb, sol.Rb
    if X is None or Y is None or Pb is None or Sb is None or Rb is None:
        # what np.linalg.inv(None) raised before: the callers treat it as no gain
        raise np.linalg.LinAlgError('the solver returned no point')
    eps = float(sol.eps)
    Xi = np.linalg.inv(X)
    K = Y @ Xi
    P1 = _sym(Xi.T @ _sym(Pb) @ Xi)
    S = _sym(Xi.T @ _sym(Sb) @ Xi)
    R = _sym(Xi.T @ _sym(Rb) @ Xi)
    P2 = Xi
    P3 = eps * Xi
    ver = _verify(problem, K, float(h), P1, P2, P3, S, R, sol.lam, verify_tol)
    return DelayDependentCertificate(K=K, h=h, eps=eps, P1=P1, P2=P2, P3=P3, S=S, R=R,
                                     lam=sol.lam, verification=ver)


def _check_args(problem: Problem, h: float, eps_grid: Sequence[float],
                gain_bound: float | None) -> None:
    if not (math.isfinite(h) and h > 0):
        raise ValueError(f'h must be a finite delay > 0 (seconds), got {h!r}')
    if gain_bound is not None and not gain_bound > 0:
        raise ValueError(f'gain_bound must be > 0, got {gain_bound!r}')
    if not len(eps_grid) or not all(math.isfinite(e) and e > 0 for e in eps_grid):
        raise ValueError(f'eps_grid must be a non-empty sequence of numbers > 0, got {eps_grid!r}')


def _describe(problem: Problem, h: float, nominal: bool, gain_bound: float | None) -> str:
    kind = 'nominal' if nominal else 'non-fragile'
    bound = '' if gain_bound is None else f', ||K||_2 <= {gain_bound:g}'
    return f'delay-dependent design ({kind}{bound}) for problem {problem.name!r} at h = {h:g}'


def synthesize_delay_dependent(problem: Problem, h: float | None = None, *,
                               eps: float | None = None,
                               eps_grid: Sequence[float] = DEFAULT_EPS_GRID,
                               refine: int = DEFAULT_REFINE, nominal: bool = False,
                               gain_bound: float | None = None, margin: float = DEFAULT_MARGIN,
                               solver: str = DEFAULT_SOLVER,
                               verify_tol: float = 1e-9) -> DelayDependentResult:
    """Delay-dependent (non-fragile) state feedback for the constant delay ``h``.

    Parameters
    ----------
    problem : Problem
        ``A, B, A_tau, E, F`` (``problem.tau`` is the default delay).
    h : float, optional
        Delay to certify (seconds, > 0); default ``problem.tau``.  The certificate
        also covers every constant delay in ``(0, h]``.
    eps : float, optional
        Tuning scalar ``P3 = eps P2``.  Default: line search over ``eps_grid`` (then
        ``refine`` golden-section steps in ``log eps``) maximizing the strictness ``t``.
    nominal : bool
        Drop the ``E D F`` terms (``D = 0``).
    gain_bound : float, optional
        Also impose ``||K||_2 <= gain_bound``.
    eps_grid : sequence of float
        The ``eps`` grid of the line search.
    refine : int
        Golden-section steps after the grid.
    margin : float
        Required strictness ``t`` (normalized units, see module docstring).
    solver : str
        cvxpy solver.
    verify_tol : float
        Relative tolerance of :func:`verify_delay_dependent`.

    Returns
    -------
    DelayDependentResult

    Raises
    ------
    InfeasibleError
        No ``eps`` tried gives ``t >= margin``.
    SolverFailure
        The solver failed for every ``eps`` tried (no point, no infeasibility proof).
    CertificateError
        The chosen point fails :func:`verify_delay_dependent`.
    """
    t0 = time.perf_counter()
    h = float(problem.tau if h is None else h)
    grid = [float(eps)] if eps is not None else [float(e) for e in eps_grid]
    _check_args(problem, h, grid, gain_bound)
    prog = _program(problem, nominal, gain_bound is not None)
    prog.set_data(problem, gain_bound)
    sols: list[DescriptorSolution] = []

    def run(e: float) -> float:
        sol = prog.solve(problem, h, e, solver)
        sols.append(sol)
        return _t_of(sol)

    if eps is not None:
        run(float(eps))
    else:
        eps_search(run, grid, refine)
    solve_time = sum(s.solve_time for s in sols)
    scan = tuple((float(s.eps), _t_of(s)) for s in sols)
    best = max(sols, key=_t_of)
    t_best = _t_of(best)
    what = _describe(problem, h, nominal, gain_bound)
    if t_best < margin:
        if t_best == -math.inf and not any(s.status in _INFEASIBLE or
                                           (s.status in _OK) for s in sols):
            raise SolverFailure(f'{what}: solver {solver} failed for every eps tried '
                                f'(statuses {sorted({s.status for s in sols})}); no gain '
                                'was produced. Check that the solver is installed.')
        best_txt = ('no feasible point' if t_best == -math.inf
                    else f'best margin t = {t_best:.3g} at eps = {best.eps:.3g}')
        e_txt = (f'eps = {grid[0]:g}' if eps is not None
                 else f'eps in [{min(grid):g}, {max(grid):g}]')
        raise InfeasibleError(
            f'{what} is infeasible: {best_txt} over {e_txt} (< required margin {margin:g}). '
            'Try a smaller h (max_certified_delay gives the largest certifiable delay), a '
            'looser gain bound, a wider eps_grid, a smaller A_tau or F, or nominal=True.')
    try:
        cert = _certificate(problem, h, best, verify_tol)
    except np.linalg.LinAlgError:
        raise CertificateError(f'{solver} returned a singular X for the {what} '
                               f'(eps = {best.eps:.3g}); no gain can be recovered') from None
    ver = cert.verification
    if not ver.ok:
        raise CertificateError(
            f'{solver} returned a point for the {what} (eps = {best.eps:.3g}) that fails '
            f'independent verification: {ver.describe()}. ' + retry_advice(solver))
    return DelayDependentResult(
        K=cert.K, h=h, eps=float(best.eps), certificate=cert, margin_required=margin,
        margin_achieved=t_best, status=str(best.status), solver=solver,
        solve_time=solve_time, wall_time=time.perf_counter() - t0, nominal=nominal,
        gain_bound=gain_bound, eps_scan=scan, extra={'solves': len(sols)})


def _feasible_at(problem: Problem, h: float, grid: list[float], start: float | None, *,
                 nominal: bool, gain_bound: float | None, margin: float, solver: str,
                 verify_tol: float,
                 refine: int = DEFAULT_REFINE) -> float | None:
    """An eps giving a verified certificate at ``h`` (None if none is found).

    :func:`.search.eps_search` over ``grid`` (locally from ``start``, the last success,
    if given), stopping at the first success; ``refine`` golden-section steps around
    the best grid point come last (near the largest certifiable delay the feasible eps
    interval becomes narrow and can fall between grid points).
    """
    prog = _program(problem, nominal, gain_bound is not None)
    prog.set_data(problem, gain_bound)

    class _Found(Exception):
        pass

    def attempt(e: float) -> float:
        sol = prog.solve(problem, h, e, solver)
        t = _t_of(sol)
        if t >= margin:
            try:
                if _certificate(problem, h, sol, verify_tol).verification.ok:
                    raise _Found(e)
            except np.linalg.LinAlgError:
                pass
        return t

    try:
        eps_search(attempt, grid, refine, start=start, accept=margin)
    except _Found as found:
        return float(found.args[0])
    return None


def max_certified_delay(problem: Problem, *, nominal: bool = False,
                        gain_bound: float | None = None, h_hi: float = 10.0,
                        tol: float = 1e-3, eps_grid: Sequence[float] = DEFAULT_EPS_GRID,
                        refine: int = DEFAULT_REFINE, margin: float = DEFAULT_MARGIN,
                        solver: str = DEFAULT_SOLVER, verify_tol: float = 1e-9
                        ) -> tuple[float, DelayDependentResult]:
    """Largest delay the delay-dependent condition certifies, by bisection on ``h``.

    Feasibility is monotone in ``h`` (module docstring, step 7).  A trial delay counts
    as certified iff some ``eps`` gives ``t >= margin`` and a verified certificate: the
    whole ``eps_grid`` until the first success, then a local climb on it from the last
    successful ``eps`` (:func:`.search.eps_search`), then ``refine`` golden-section steps
    around the best grid point; the first success stops the search.  Because ``eps`` is
    searched heuristically the result is a lower bound of the largest delay the LMI
    family certifies.  The bracket
    ``[lo, hi]`` is found by halving ``h_hi`` and bisected until ``hi - lo <= tol``.
    Returns ``(lo, result)``, ``result`` the full line search (with refinement) at ``lo``
    (``result.eps`` may differ from the ``eps`` that decided feasibility).  ``lo == h_hi``
    means ``h_hi`` itself is certified (the condition may hold for every delay, e.g. ``A_tau = 0``).

    Parameters
    ----------
    problem : Problem
        The data ``A, B, A_tau, E, F``.
    nominal : bool, optional
        Drop the ``E D F`` terms.
    gain_bound : float, optional
        ``||K||_2`` bound.
    h_hi : float, optional
        Largest delay tried (s).
    tol : float, optional
        Absolute width of the final bracket (s).
    eps_grid, refine, margin, solver, verify_tol
        As in :func:`synthesize_delay_dependent`.

    Returns
    -------
    h : float
        The largest certified delay found (s).
    result : DelayDependentResult
        The design at ``h``.

    Raises
    ------
    InfeasibleError
        Not even the smallest delay tried (below ``tol``) is certified.
    """
    if not (math.isfinite(h_hi) and h_hi > 0 and tol > 0):
        raise ValueError(f'need h_hi > 0 and tol > 0, got h_hi={h_hi!r}, tol={tol!r}')
    kw: dict[str, Any] = dict(nominal=nominal, gain_bound=gain_bound, margin=margin,
                              solver=solver, verify_tol=verify_tol)
    grid = sorted(float(e) for e in eps_grid)
    _check_args(problem, h_hi, grid, gain_bound)
    last: list[float] = []

    def ok(h: float) -> bool:
        e = _feasible_at(problem, h, grid, last[-1] if last else None, refine=refine, **kw)
        if e is not None:
            last.append(e)
        return e is not None

    def final(h: float) -> DelayDependentResult:
        return synthesize_delay_dependent(problem, h, eps_grid=grid, refine=refine, **kw)

    if ok(h_hi):
        return h_hi, final(h_hi)
    hi, lo = h_hi, 0.5 * h_hi
    while not ok(lo):
        hi = lo
        if lo < tol:
            raise InfeasibleError(
                f'{_describe(problem, lo, nominal, gain_bound)} is infeasible, and so for '
                f'every delay tried down to h = {lo:g} (eps in [{grid[0]:g}, {grid[-1]:g}]). '
                'Check that the loop is stabilizable for small delays with this gain bound: '
                'try a looser gain bound, nominal=True, a smaller F, or a wider eps_grid.')
        lo *= 0.5
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    try:
        res = final(lo)
    except (InfeasibleError, CertificateError):
        # the full search ran with refinement; fall back to the eps that succeeded
        res = synthesize_delay_dependent(problem, lo, eps=last[-1], **kw)
    return lo, res
