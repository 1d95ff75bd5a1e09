r"""Non-fragile state feedback certified for an input (command) latency in an interval.

Closed loop (the command computed from the state acts ``h(t)`` seconds later)::

    x'(t) = A x(t) + A_tau x(t - tau) + B (K + E D(t) F) x(t - h(t)),
    h_min <= h(t) <= h_max,   D(t)^T D(t) <= I,

with ``h(t)`` and ``D(t)`` time-varying without a rate bound; ``A_tau`` is handled
delay-independently, as in Theorem 1 (:mod:`.lmi`).  Certificates are verified in numpy
(:func:`.input_delay_certificate.verify_input_delay`).

See doc/theory.md, section "Input delay (command latency)" (#input-delay-command-latency):
the sources, the functional, the derivation, normalisation and caveats.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence, cast

import numpy as np

from .errors import CertificateError, InfeasibleError, SolverFailure
from ...errors import InputError
# the records and the numpy check, importable from here as before (explicit re-exports)
from .input_delay_certificate import (InputDelayCertificate, InputDelayResult,
                                      InputDelayVerification, Weights, check_interval,
                                      input_delay_verification_matrix, phi_rows,
                                      verify_input_delay, weights)
from .problem import Problem
from .sdp import (DEFAULT_MARGIN, DEFAULT_SOLVER, INFEASIBLE_STATUSES, OK_STATUSES,
                  DescriptorParameters, SolveOutcome, cached_program, solve, solve_for_point,
                  sym)
from .search import eps_search, largest_feasible_bracketed

__all__ = ['DEFAULT_EPS_GRID', 'InputDelayVerification', 'InputDelayCertificate',
           'InputDelayResult', 'InputDelayCertification', 'certify_input_delay',
           'certified_input_delay_of_gain', 'input_delay_verification_matrix', 'verify_input_delay',
           'synthesize_input_delay', 'max_certified_input_delay', 'max_input_delay_decay_rate']

DEFAULT_EPS_GRID: tuple[float, ...] = tuple(float(e) for e in np.logspace(-3, 2, 21))
DEFAULT_REFINE = 8


# ---------------------------------------------------------------------------------------------
# the SDP (one per shape/options, re-solved with new data through DPP parameters)

@dataclass(frozen=True)
class _Point:
    status: str
    t: float | None
    solve_time: float
    eps: float
    values: dict[str, Any] | None = None

    @property
    def strictness(self) -> float:
        if self.status not in OK_STATUSES or self.t is None or self.values is None:
            return -math.inf
        return float(self.t)


class _InputDelayProgram(DescriptorParameters):
    def __init__(self, n: int, m: int, q: int, p: int, nominal: bool, gain_bound: bool,
                 state_delay: bool):
        import cvxpy as cp
        par, var = cp.Parameter, cp.Variable
        self.nominal, self.state_delay = nominal, state_delay
        self.A, self.B, self.Ad = par((n, n)), par((n, m)), par((n, n))
        self.eA, self.eB, self.eAd = par((n, n)), par((n, m)), par((n, n))
        self.eps, self.two_a = par(nonneg=True), par(nonneg=True)
        self.w0, self.w1, self.wt = par(nonneg=True), par(nonneg=True), par(nonneg=True)
        self.h0sq, self.h10sq = par(nonneg=True), par(nonneg=True)
        self.X, self.Y = var((n, n)), var((m, n))
        sv = {k: var((n, n), symmetric=True) for k in ('Pb', 'S0b', 'S1b', 'R0b', 'R1b', 'Qb')}
        self.sv = sv
        self.S12b = var((n, n))
        self.t = var()
        X, Y = self.X, self.Y
        Pb, S0b, S1b, R0b, R1b, Qb = (sv[k] for k in ('Pb', 'S0b', 'S1b', 'R0b', 'R1b', 'Qb'))
        S12b = self.S12b
        Z = np.zeros((n, n))
        AX = self.A @ X
        b11 = AX + AX.T + self.two_a * Pb + S0b - self.w0 * R0b
        b12 = Pb - X + (self.eA @ X).T
        b22 = -self.eps * (X + X.T) + self.h0sq * R0b + self.h10sq * R1b
        BY, eBY = self.B @ Y, self.eB @ Y
        w1 = self.w1
        rows = [
            [b11, b12, self.w0 * R0b, BY, Z],
            [b12.T, b22, Z, eBY, Z],
            [self.w0 * R0b, Z, self.w0 * (S1b - S0b - R0b) - w1 * R1b, w1 * (R1b - S12b),
             w1 * S12b],
            [BY.T, eBY.T, w1 * (R1b - S12b).T, w1 * (S12b + S12b.T - 2 * R1b),
             w1 * (R1b - S12b)],
            [Z, Z, w1 * S12b.T, w1 * (R1b - S12b).T, -w1 * (S1b + R1b)],
        ]
        lyap = [Pb, S0b, S1b, R0b, R1b]
        if state_delay:
            rows[0][0] = rows[0][0] + Qb
            cols = [self.Ad @ X, self.eAd @ X, Z, Z, Z]
            for r, c in zip(rows, cols):
                r.append(c)
            rows.append([c.T for c in cols] + [-self.wt * Qb])
            lyap.append(Qb)
        k = len(rows)
        size = k * n
        extra = []
        if nominal:
            self.lam = None
        else:
            self.BE, self.eBE, self.F = par((n, q)), par((n, q)), par((p, n))
            self.lam = lam = var()
            U = [lam * self.BE, lam * self.eBE] + [np.zeros((n, q))] * (k - 2)
            FX = (self.F @ X).T
            V = [np.zeros((n, p))] * 3 + [FX] + [np.zeros((n, p))] * (k - 4)
            for r, u, v in zip(rows, U, V):
                r.extend([u, v])
            rows.append([u.T for u in U] + [-lam * np.eye(q), np.zeros((q, p))])
            rows.append([v.T for v in V] + [np.zeros((p, q)), -lam * np.eye(p)])
            size += q + p
            extra = [lam >= self.t]
        L = cp.bmat(rows)
        L = 0.5 * (L + L.T)
        In = np.eye(n)
        RC = cp.bmat([[R1b, S12b], [S12b.T, R1b]])
        self.L, self.lmi = L, L << -self.t * np.eye(size)
        cons = [self.lmi, 0.5 * (RC + RC.T) >> self.t * np.eye(2 * n)]
        cons += [M >> self.t * In for M in lyap] + extra
        if gain_bound:
            cons += self.gain_bound_constraints(X, Y, self.t)
        else:
            norm = sum(cp.trace(M) for M in lyap) + cp.trace(X)
            if self.lam is not None:
                norm = norm + self.lam
            cons += [norm <= 1]
        self.problem = cp.Problem(cp.Maximize(self.t), cons)
        self._data: Any = None
        self._last: tuple[Any, _Point] | None = None

    def set_data(self, problem: Problem, kappa: float | None) -> None:
        data = (tuple(np.asarray(M, float).tobytes() for M in (
            problem.A, problem.B, problem.A_tau, problem.E, problem.F)), float(problem.tau),
            None if kappa is None else float(kappa))
        if data != self._data:
            self._data, self._last = data, None
        self.set_problem(problem, kappa)

    def solve(self, problem: Problem, h0: float, h1: float, alpha: float, eps: float,
              solver: str) -> _Point:
        # the same data solved again (a search's last single-eps trial, then the climb from
        # that eps at the same point) gives the same point: the solver is deterministic
        key = (self._data, float(h0), float(h1), float(alpha), float(eps), solver)
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        point = self._solve(problem, h0, h1, alpha, eps, solver)
        self._last = (key, point)
        return point

    def _solve(self, problem: Problem, h0: float, h1: float, alpha: float, eps: float,
               solver: str) -> _Point:
        self.set_eps(problem, eps)
        self.two_a.value = 2.0 * alpha
        self.w0.value = math.exp(-2 * alpha * h0)
        self.w1.value = math.exp(-2 * alpha * h1)
        self.wt.value = math.exp(-2 * alpha * problem.tau)
        self.h0sq.value, self.h10sq.value = h0 * h0, (h1 - h0) ** 2
        out, t, usable = solve_for_point(self.problem, solver, 'the input-delay LMI', self.t,
                                         self.X)
        if usable:
            vals: dict[str, Any] = {k: np.array(v.value) for k, v in self.sv.items()}
            vals.update(X=np.array(self.X.value), Y=np.array(self.Y.value),
                        S12b=np.array(self.S12b.value),
                        lam=None if self.lam is None else float(np.asarray(self.lam.value)))
            return _Point(out.status, t, out.solve_time, eps, vals)
        return _Point(out.status, t, out.solve_time, eps)


def _alpha_slope(prog: _InputDelayProgram, h0: float, h1: float, alpha: float,
                 tau: float) -> float:
    """``d t / d alpha`` of the program's last solve, at its ``eps`` (envelope theorem).

    ``alpha`` enters the LMI only through its weights ``2 alpha``, ``exp(-2 alpha h_min)``,
    ``exp(-2 alpha h_max)`` and ``exp(-2 alpha tau)``, each multiplying decision variables
    linearly, so ``dL/d alpha`` is the sum of the weights' derivatives times the change
    of the solved ``L`` under a unit change of each weight, and with ``Z >= 0`` the dual of
    ``L <= -t I`` the optimal ``t`` changes by ``-<Z, dL/d alpha>`` (first order).  ``nan``
    when the solver gave no dual.  A search figure only, never part of a certificate.
    """
    Z = prog.lmi.dual_value
    if Z is None:
        return math.nan
    derivs = ((prog.two_a, 2.0), (prog.w0, -2.0 * h0 * math.exp(-2.0 * alpha * h0)),
              (prog.w1, -2.0 * h1 * math.exp(-2.0 * alpha * h1)),
              (prog.wt, -2.0 * tau * math.exp(-2.0 * alpha * tau)))
    L0 = np.asarray(prog.L.value, float)
    dL = np.zeros_like(L0)
    for par, d in derivs:
        v = par.value
        try:
            par.value = float(np.asarray(v)) + 1.0
            dL += d * (np.asarray(prog.L.value, float) - L0)
        finally:
            par.value = v
    out = -float(np.sum(np.asarray(Z, float) * dL))
    return out if math.isfinite(out) else math.nan


def _uses_state_delay(problem: Problem, state_delay: bool | None) -> bool:
    return bool(np.any(problem.A_tau)) if state_delay is None else bool(state_delay)


def _program(problem: Problem, nominal: bool, gain_bound: bool, state_delay: bool
             ) -> _InputDelayProgram:
    shape = (problem.n, problem.m, problem.E.shape[1], problem.F.shape[0], nominal,
             gain_bound, state_delay)
    return cached_program(('input_delay',) + shape, lambda: _InputDelayProgram(*shape))


def _back(point: _Point, state_delay: bool) -> tuple[np.ndarray, InputDelayCertificate]:
    v = point.values
    assert v is not None
    Xi = np.linalg.inv(v['X'])

    def orig(M: np.ndarray) -> np.ndarray:
        return cast(np.ndarray, Xi.T @ M @ Xi)

    K = v['Y'] @ Xi
    cert = InputDelayCertificate(
        P=sym(orig(sym(v['Pb']))), P2=Xi, P3=point.eps * Xi, S0=sym(orig(sym(v['S0b']))),
        S1=sym(orig(sym(v['S1b']))), R0=sym(orig(sym(v['R0b']))),
        R1=sym(orig(sym(v['R1b']))), S12=orig(v['S12b']),
        Q=sym(orig(sym(v['Qb']))) if state_delay else None, lam=v['lam'])
    return K, cert


# ---------------------------------------------------------------------------------------------
# argument checks

def _check(gain_bound: Any, alpha: Any, grid: Sequence[float]) -> None:
    if gain_bound is not None and not (isinstance(gain_bound, (int, float))
                                       and math.isfinite(gain_bound) and gain_bound > 0):
        raise InputError(f'gain bound must be a finite number > 0, got {gain_bound!r}')
    if not (isinstance(alpha, (int, float)) and math.isfinite(alpha) and alpha >= 0):
        raise InputError(f'decay rate alpha must be a finite number >= 0, got {alpha!r}')
    if not len(grid) or not all(math.isfinite(e) and e > 0 for e in grid):
        raise InputError(f'eps grid must be non-empty numbers > 0, got {grid!r}')


def _describe(problem: Problem, h0: float, h1: float, alpha: float, nominal: bool,
              gain_bound: float | None) -> str:
    kind = 'nominal' if nominal else 'non-fragile'
    bound = '' if gain_bound is None else f', ||K||_2 <= {gain_bound:g}'
    rate = f', decay rate {alpha:g}' if alpha else ''
    return (f'input-delay design ({kind}{bound}{rate}) for problem {problem.name!r} with '
            f'h in [{h0:g}, {h1:g}] s')


# ---------------------------------------------------------------------------------------------
# synthesis

_Checked = tuple[np.ndarray, InputDelayCertificate, InputDelayVerification]
_Found = tuple[_Point, np.ndarray, InputDelayCertificate, InputDelayVerification]


class _Stop(Exception):
    """The first verified point of a ``stop_at_first`` search was found."""


def _checked(problem: Problem, pt: _Point, sd: bool, h0: float, h1: float, alpha: float,
             verify_tol: float) -> _Checked | None:
    """``(K, certificate, verification)`` of a solver point (``None``: singular ``X``)."""
    try:
        K, cert = _back(pt, sd)
    except np.linalg.LinAlgError:
        return None
    ver = verify_input_delay(problem, K, h0, h1, cert, alpha=alpha, tol=verify_tol)
    return K, cert, ver


def _search_eps(solve_at: Callable[[float], _Point], check: Callable[[_Point], _Checked | None],
                grid: list[float], eps: float | None, refine: int, eps_start: float | None,
                margin: float, stop_at_first: bool) -> tuple[list[_Point], _Found | None]:
    """The points of the ``eps`` search of :func:`synthesize_input_delay`, in solve order.

    With ``stop_at_first`` the search stops at the first point with ``t >= margin`` that
    passes ``check``; that point is returned second (``None`` otherwise).
    """
    points: list[_Point] = []
    found: list[_Found] = []

    def run(e: float) -> float:
        pt = solve_at(e)
        points.append(pt)
        t = pt.strictness
        if stop_at_first and t >= margin:
            v = check(pt)
            if v is not None and v[2].ok:
                found.append((pt,) + v)
                raise _Stop
        return t

    try:
        if eps is not None:
            run(float(eps))
        else:
            # a warm-started trial of a search whose point is rejected by the independent
            # check stops at the climb's local maximum (the search counts it as failed,
            # just beyond the boundary) instead of scanning the whole grid
            eps_search(run, grid, refine, start=eps_start,
                       accept=margin if stop_at_first and eps_start is None else math.inf)
    except _Stop:
        pass
    return points, (found[-1] if found else None)


def _strictest_verified(points: list[_Point], check: Callable[[_Point], _Checked | None],
                        margin: float, what: str, solver: str) -> _Found:
    """The strictest point with ``t >= margin`` that passes ``check``, or the error why none.

    Raises ``SolverFailure`` (no status of a solve), ``InfeasibleError`` (no point with
    ``t >= margin``) or ``CertificateError`` (none passes the independent check); the
    latter two carry the best ``t`` as ``margin_achieved``.
    """
    best = max(points, key=lambda p: p.strictness)
    if best.strictness < margin:
        if not any(p.status in OK_STATUSES + INFEASIBLE_STATUSES for p in points):
            raise SolverFailure(f'{what}: solver {solver} failed for every eps tried '
                                f'(statuses {sorted({p.status for p in points})}); no '
                                'gain was produced. Check that the solver is installed.')
        txt = ('no feasible point' if best.strictness == -math.inf
               else f'best margin t = {best.strictness:.3g} at eps = {best.eps:.3g}')
        err = InfeasibleError(
            f'{what} is infeasible: {txt} (< required margin {margin:g}). Try a smaller '
            'h_max (max_certified_input_delay gives the largest), a looser gain bound, a '
            'smaller decay rate, a smaller F, or nominal=True.')
        err.margin_achieved = float(best.strictness)
        raise err
    # refinement: a point that fails the independent check (typically only its relative
    # tolerance, near the feasibility boundary) is replaced by the strictest other point
    # already solved that passes it - every eps point of the search is a candidate
    usable = sorted((p for p in points if p.strictness >= margin), key=lambda p: -p.strictness)
    first: tuple[_Point, _Checked | None] | None = None
    for cand in usable:
        v = check(cand)
        if v is not None and v[2].ok:
            return (cand,) + v
        first = first or (cand, v)
    cand, v = first if first is not None else (best, None)
    if v is None:
        raise CertificateError(f'{solver} returned a singular X for the {what}; no '
                               'gain can be recovered')
    ver = v[2]
    cerr = CertificateError(
        f'{solver} returned no point for the {what} that passes independent '
        f'verification ({len(usable)} with t >= {margin:g}; strictest at eps = '
        f'{cand.eps:.3g}: {ver.describe()}, relative tolerance {ver.tolerance:g} x '
        f'{ver.scale:.3g}). The point is at the edge of feasibility: ask for '
        'a little less (smaller h_max or decay rate) or a larger margin '
        '(options.margin of the problem).')
    cerr.margin_achieved = float(cand.strictness)
    raise cerr


def synthesize_input_delay(problem: Problem, h_min: float, h_max: float, *,
                           alpha: float = 0.0, eps: float | None = None,
                           eps_grid: Sequence[float] = DEFAULT_EPS_GRID,
                           refine: int = DEFAULT_REFINE, nominal: bool = False,
                           gain_bound: float | None = None, state_delay: bool | None = None,
                           margin: float = DEFAULT_MARGIN, solver: str = DEFAULT_SOLVER,
                           verify_tol: float = 1e-9, stop_at_first: bool = False,
                           eps_start: float | None = None) -> InputDelayResult:
    """A gain certified for every input delay ``h(t)`` in ``[h_min, h_max]``.

    Parameters
    ----------
    problem : Problem
        ``A, B, E, F`` (and ``A_tau, tau`` for the state-delay term).
    h_min, h_max : float
        Latency interval in seconds, ``0 <= h_min <= h_max``, ``h_max > 0``.
    alpha : float
        Certified decay rate (1/s), ``>= 0``.
    eps : float, optional
        Tuning scalar ``P3 = eps P2``; default: grid ``eps_grid`` then ``refine``
        golden-section steps in ``log eps`` maximizing the strictness ``t``
        (:func:`.search.eps_search`).
    nominal : bool
        Drop the ``E D F`` terms.
    gain_bound : float, optional
        Impose ``||K||_2 <= gain_bound``.
    state_delay : bool, optional
        Include ``A_tau x(t - tau)``; default: iff ``A_tau != 0``.
    stop_at_first : bool
        Return the first ``eps`` giving a verified certificate (bisection uses this).
    eps_start : float, optional
        Warm start of the ``eps`` search: a local climb on ``eps_grid`` from this value
        instead of the whole grid (the bisections pass the ``eps`` of their last
        success).
    eps_grid : sequence of float
        The ``eps`` grid.
    refine : int
        Golden-section steps after the grid.
    margin : float
        Required strictness ``t`` (normalised units).
    solver : str
        cvxpy solver.
    verify_tol : float
        Relative tolerance of :func:`.input_delay_certificate.verify_input_delay`.

    Returns
    -------
    InputDelayResult
        Gain, certificate and its independent verification (always ``ok``).

    Raises
    ------
    InputError
        Bad interval, bound, rate or grid.
    InfeasibleError
        No ``eps`` tried gives ``t >= margin`` with a verified certificate.
    SolverFailure
        The solver failed for every ``eps`` tried.
    CertificateError
        The best point fails :func:`.input_delay_certificate.verify_input_delay`.
    """
    t0 = time.perf_counter()
    h0, h1 = check_interval(h_min, h_max)
    grid = [float(eps)] if eps is not None else [float(e) for e in eps_grid]
    _check(gain_bound, alpha, grid)
    if eps_start is not None and not (isinstance(eps_start, (int, float))
                                      and math.isfinite(eps_start) and eps_start > 0):
        raise InputError(f'eps_start must be a finite number > 0, got {eps_start!r}')
    alpha = float(alpha)
    sd = _uses_state_delay(problem, state_delay)
    prog = _program(problem, nominal, gain_bound is not None, sd)
    prog.set_data(problem, gain_bound)

    def check(pt: _Point) -> _Checked | None:
        return _checked(problem, pt, sd, h0, h1, alpha, verify_tol)

    def solve_at(e: float) -> _Point:
        return prog.solve(problem, h0, h1, alpha, e, solver)

    points, found = _search_eps(solve_at, check, grid, eps, refine, eps_start, margin,
                                stop_at_first)
    solve_time = sum(p.solve_time for p in points)
    scan = tuple((p.eps, p.strictness) for p in points)
    what = _describe(problem, h0, h1, alpha, nominal, gain_bound)
    if found is None:
        found = _strictest_verified(points, check, margin, what, solver)
    best, K, cert, ver = found
    return InputDelayResult(
        K=K, h_min=h0, h_max=h1, alpha=alpha, eps=best.eps, certificate=cert,
        verification=ver, margin_required=margin, margin_achieved=float(best.strictness),
        status=best.status, solver=solver, solve_time=solve_time,
        wall_time=time.perf_counter() - t0, nominal=nominal, state_delay=sd,
        gain_bound=gain_bound, eps_scan=scan, extra={'solves': len(points)})


@dataclass(frozen=True)
class InputDelayCertification:
    """Whether a fixed ``K`` is certified for input delays in ``[h_min, h_max]``."""

    certified: bool
    margin_achieved: float                   # best t (normalized units); -inf: no point
    certificate: InputDelayCertificate | None
    verification: InputDelayVerification | None
    status: str
    #: ``d t / d h_max`` at the solution (envelope theorem, from the dual of the LMI; see
    #: :func:`certify_input_delay`); ``nan`` when the solver gave no dual
    slope: float = math.nan


class _CertifyProgram:
    """The fixed-gain certification LMI of :func:`certify_input_delay`, compiled once.

    The problem's matrices, ``B K`` and the weights are parameters: one program per shape.
    """

    def __init__(self, n: int, q: int, p: int, nominal: bool, state_delay: bool):
        import cvxpy as cp
        par, var = cp.Parameter, cp.Variable
        self.nominal = nominal
        self.A, self.A1, self.Ad = par((n, n)), par((n, n)), par((n, n))
        self.wts = Weights(*(par(nonneg=True) for _ in Weights._fields))
        sv = {k: var((n, n), symmetric=True) for k in ('P', 'S0', 'S1', 'R0', 'R1', 'Q')}
        self.sv = sv
        self.P2, self.P3, self.S12, self.t = var((n, n)), var((n, n)), var((n, n)), var()
        P2, P3, S12, t = self.P2, self.P3, self.S12, self.t
        rows = phi_rows(self.A, self.A1, self.Ad, self.wts, sv['P'], P2, P3, sv['S0'],
                         sv['S1'], sv['R0'], sv['R1'], S12, sv['Q'] if state_delay else None)
        lyap = [sv[k] for k in ('P', 'S0', 'S1', 'R0', 'R1')] + (
            [sv['Q']] if state_delay else [])
        norm = sum(cp.trace(M) for M in lyap)
        cons = []
        self.d = None
        k = len(rows)
        if not nominal:
            self.FtF, self.BE = par((n, n)), par((n, q))
            self.d = d = var()
            rows[3][3] = rows[3][3] + d * self.FtF
            U = [P2.T @ self.BE, P3.T @ self.BE] + [np.zeros((n, q))] * (k - 2)
            for r, u in zip(rows, U):
                r.append(u)
            rows.append([u.T for u in U] + [-d * np.eye(q)])
            norm = norm + d
            cons.append(d >= t)
        L = cp.bmat(rows)
        L = 0.5 * (L + L.T)
        RC = cp.bmat([[sv['R1'], S12], [S12.T, sv['R1']]])
        self.lmi = L << -t * np.eye(L.shape[0])
        cons += [self.lmi, 0.5 * (RC + RC.T) >> t * np.eye(2 * n), norm <= 1]
        cons += [M >> t * np.eye(n) for M in lyap]
        self.problem = cp.Problem(cp.Maximize(t), cons)

    def solve(self, problem: Problem, K: np.ndarray, weights: Weights, solver: str
              ) -> SolveOutcome:
        self.A.value, self.A1.value = problem.A, problem.B @ K
        self.Ad.value = problem.A_tau
        for p, v in zip(self.wts, weights):
            p.value = v
        if not self.nominal:
            self.FtF.value = problem.F.T @ problem.F
            self.BE.value = problem.B @ problem.E
        return solve(self.problem, solver, what='the input-delay certification LMI for K',
                     quiet_inaccurate=True)


def certify_input_delay(problem: Problem, K: Any, h_min: float, h_max: float, *,
                        alpha: float = 0.0, nominal: bool = False,
                        state_delay: bool | None = None, margin: float = DEFAULT_MARGIN,
                        solver: str = DEFAULT_SOLVER, verify_tol: float = 1e-9
                        ) -> InputDelayCertification:
    """Decide whether the input-delay condition holds for the fixed gain ``K``.

    With ``K`` fixed, ``Psi < 0`` is an LMI in ``(P, P2, P3, S0, S1, R0, R1, S12, Q)`` and
    ``d = 1/lam`` after the Schur complement
    ``[[Phi_0 + d V^T V, U], [U^T, -d I]] < 0`` (no tuning scalar is needed); solved as
    ``maximize t`` with every block ``<= -t I`` / ``>= t I`` and a trace bound, and
    certified iff ``t >= margin`` and :func:`.input_delay_certificate.verify_input_delay` passes.

    ``slope`` of the result is ``d t / d h_max`` at the solution, by the envelope theorem:
    ``h_max`` enters only the weights ``(h_max - h_min)^2`` and ``exp(-2 alpha h_max)`` of
    ``Phi_0``, each linearly, so with ``Z >= 0`` the dual of ``L <= -t I`` the derivative of
    the optimal ``t`` is ``-<Z, dL/dh_max>`` (``dL/dh_max``: ``Phi_0`` of the solved matrices
    with the weights' derivatives).  It is a first-order figure for the searches (one solve
    gives a Newton step), never part of a certificate (test/control/test_dual_slopes.py
    compares it with finite differences).

    Parameters
    ----------
    problem : Problem
        The loop (state delay as ``state_delay`` decides).
    K : array_like, shape (m, n)
        The gain.
    h_min, h_max : float
        The latency interval (s).
    alpha : float, optional
        The decay rate the certificate must show (1/s).
    nominal : bool, optional
        Certify ``D = 0`` only.
    state_delay : bool, optional
        Include ``A_tau x(t - tau)``; default: iff ``A_tau != 0``.
    margin : float, optional
        Required strictness.
    solver : str, optional
        cvxpy solver.
    verify_tol : float, optional
        Relative tolerance of :func:`.input_delay_certificate.verify_input_delay`.

    Returns
    -------
    InputDelayCertification
    """
    h0, h1 = check_interval(h_min, h_max)
    _check(None, alpha, [1.0])
    K = problem.gain(K)
    sd = _uses_state_delay(problem, state_delay)
    key = ('input_delay_certify', problem.n, problem.E.shape[1], problem.F.shape[0], nominal,
           sd)
    prog = cached_program(key, lambda: _CertifyProgram(*key[1:]))
    out = prog.solve(problem, K, weights(h0, h1, alpha, problem.tau), solver)
    values = {k: v.value for k, v in prog.sv.items()}
    t, d = prog.t.value, None if prog.d is None else prog.d.value
    if out.status not in OK_STATUSES or t is None or values['P'] is None:
        return InputDelayCertification(False, -math.inf, None, None, out.status)
    tv = float(t)
    if tv < margin:
        return InputDelayCertification(False, tv, None, None, out.status)
    cert = InputDelayCertificate(
        P=sym(np.asarray(values['P'])), P2=np.array(prog.P2.value),
        P3=np.array(prog.P3.value), S0=sym(np.asarray(values['S0'])),
        S1=sym(np.asarray(values['S1'])), R0=sym(np.asarray(values['R0'])),
        R1=sym(np.asarray(values['R1'])), S12=np.array(prog.S12.value),
        Q=sym(np.asarray(values['Q'])) if sd else None,
        lam=None if d is None else 1.0 / float(d))
    ver = verify_input_delay(problem, K, h0, h1, cert, alpha=alpha, tol=verify_tol)
    return InputDelayCertification(ver.ok, tv, cert, ver, out.status,
                                   _slope(prog, problem, K, cert, h0, h1, alpha))


def _slope(prog: _CertifyProgram, problem: Problem, K: np.ndarray,
           cert: InputDelayCertificate, h0: float, h1: float, alpha: float) -> float:
    """``d t / d h_max`` of the solved certification LMI (:func:`certify_input_delay`)."""
    Z = prog.lmi.dual_value
    if Z is None:
        return math.nan
    Z = np.asarray(Z, float)
    c = cert
    d_w1 = -2.0 * alpha * math.exp(-2.0 * alpha * h1)
    zero = Weights(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    unit = Weights(0.0, 0.0, d_w1, 0.0, 0.0, 2.0 * (h1 - h0))

    def phi(w: Weights) -> np.ndarray:
        return np.block(phi_rows(problem.A, problem.B @ K, problem.A_tau, w, c.P, c.P2, c.P3,
                                  c.S0, c.S1, c.R0, c.R1, c.S12, c.Q))

    dL = phi(unit) - phi(zero)
    k = dL.shape[0]
    out = -float(np.sum(Z[:k, :k] * sym(dL)))
    return out if math.isfinite(out) else math.nan


def certified_input_delay_of_gain(problem: Problem, K: Any, h_min: float = 0.0, *,
                                  alpha: float = 0.0, nominal: bool = False,
                                  state_delay: bool | None = None, h_hi: float = 2.0,
                                  tol: float = 1e-3, solver: str = DEFAULT_SOLVER,
                                  h_certified: float | None = None,
                                  certified_margin: float | None = None,
                                  h_hi_refuted: bool = False,
                                  h_guess: float | None = None,
                                  certified_slope: float | None = None) -> float:
    """Largest ``h_max`` for which :func:`certify_input_delay` certifies ``K``.

    Returns ``h_min`` if not even ``[h_min, max(h_min, tol)]`` is certified and
    ``h_hi`` if ``h_hi`` is.  Monotone in ``h_max`` (docstring step 7), so the answer is
    bracketed and searched by false position on the certification LMI's strictness
    ``t - margin`` (:func:`.search.largest_feasible_bracketed`; ``t`` falls continuously
    through the margin and is pinned near 0 further out, by the trace normalization),
    with bisection as the safeguard.  Without ``h_certified`` it is plain bisection from
    ``h_min`` (the figures of ``design``/``synthesize`` stay bit-identical).

    Parameters
    ----------
    problem : Problem
        The loop (state delay included as :func:`certify_input_delay` decides).
    K : array_like
        The gain.
    h_min : float
        Low end of the latency interval (s).
    alpha : float
        Decay rate the certificate must show.
    nominal : bool
        Certify ``D = 0`` only.
    state_delay : bool, optional
        As in :func:`certify_input_delay`.
    h_hi : float
        Upper end of the search (s).
    tol : float
        Absolute tolerance (s) of the returned value (a certified lower bound).
    solver : str
        cvxpy solver.
    h_certified : float, optional
        An ``h_max`` already known certified for ``K`` (e.g. by its synthesis): the
        search starts there instead of at ``h_min``.
    certified_margin : float, optional
        The strictness ``t`` of :func:`certify_input_delay` at ``h_certified``, if the
        caller has it (saves that solve).
    h_hi_refuted : bool
        ``h_hi`` is known not certifiable (e.g. the exact delay margin of the loop: a
        root on the imaginary axis there), so it is not tried.
    h_guess : float, optional
        Where to try first inside the bracket (with ``h_certified``), e.g. a fraction of
        the exact margin: a good guess leaves a short bracket for the search.
    certified_slope : float, optional
        ``d t / d h_max`` at ``h_certified`` (:attr:`InputDelayCertification.slope`), with
        ``certified_margin``: the Newton steps below start without another solve.

    Notes
    -----
    With ``h_certified``, before the bracketed search, Newton steps on the strictness:
    from the largest certified ``h`` with score ``s = t - margin > 0`` and slope
    ``g = dt/dh < 0`` (from the dual of the same solve, :func:`certify_input_delay`) the
    next trial is ``h + s / (-g)``.  On the paper's loops ``t(h)`` is convex and decreasing
    near the boundary (its slope falls from -2.4e-4 to -1.8e-4 per second over the last
    10 ms), so the tangent's root lies *below* the boundary: each step lands on a certified
    ``h``, and it converges quadratically (the first step from 0.8 of the exact margin
    leaves 1e-4 s, the second 1e-6 s).  The search stops when the remaining gain is
    estimated below ``tol / 2`` (every value returned is a trial that was certified and verified in
    numpy); a step that is not certified, or a slope that is not usable, hands the bracket
    to :func:`.search.largest_feasible_bracketed` as before.  The bracketed search's
    "within ``tol`` of a refuted ``h``" becomes "the estimated remaining gain is below
    ``tol / 2``" (a model, not a refutation: the next step, or where steps shrink only
    linearly - a strictness kinked near the boundary, as on the paper's loop without the
    lag, steps 7.9, 2.8, 1.1 ms - the geometric tail of steps at the ratio of the last
    two); what is returned is a certified lower bound either way.
    """
    slopes: dict[float, float] = {}

    def trial(h1: float) -> tuple[float, bool | None]:
        c = certify_input_delay(problem, K, h_min, h1, alpha=alpha, nominal=nominal,
                                state_delay=state_delay, solver=solver)
        slopes[float(h1)] = c.slope
        score = c.margin_achieved - DEFAULT_MARGIN     # continuous through the margin
        return (score if math.isfinite(score) else math.nan), (True if c.certified else None)

    lo = max(float(h_min), tol)
    lo_s: float = math.nan
    if h_certified is not None and lo < h_certified < h_hi:
        if certified_margin is not None:
            lo, lo_s = float(h_certified), float(certified_margin) - DEFAULT_MARGIN
            if certified_slope is not None:
                slopes[lo] = float(certified_slope)
        else:
            lo_s, ok = trial(float(h_certified))
            if ok is not None:
                lo = float(h_certified)
    if lo != h_certified:
        lo_s, ok = trial(lo)
        if ok is None:
            return float(h_min)
    if not h_hi_refuted:
        _, ok = trial(h_hi)
        if ok is not None:
            return float(h_hi)
    if h_certified is None:     # plain bisection, as before the bracketed search
        hi = h_hi
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            if trial(mid)[1] is not None:
                lo = mid
            else:
                hi = mid
        return lo
    hi, hi_s = h_hi, math.nan
    if h_guess is not None and lo + tol < h_guess < hi - tol:
        sc, ok = trial(float(h_guess))
        if ok is not None:
            lo, lo_s = float(h_guess), sc
        else:
            hi, hi_s = float(h_guess), sc
    done, lo, lo_s, hi, hi_s = _newton_steps(trial, slopes, lo, lo_s, hi, hi_s, tol)
    if done:
        return float(lo)
    x, _, _ = largest_feasible_bracketed(trial, lo, hi, True, tol=tol, lo_score=lo_s,
                                         hi_score=hi_s)
    return float(x)


def _newton_steps(trial: Callable[[float], tuple[float, bool | None]],
                  slopes: dict[float, float], lo: float, lo_s: float, hi: float, hi_s: float,
                  tol: float) -> tuple[bool, float, float, float, float]:
    """Newton steps on the strictness from the certified ``lo`` (the search's Notes).

    See :func:`certified_input_delay_of_gain`.  ``trial(h) -> (t - margin, True or
    None)`` records ``slopes[h]``.  Returns ``(done, lo, lo_s, hi, hi_s)``: ``done``
    when the estimated remaining gain is below ``tol / 2`` (``lo`` is the answer), else
    the bracket for the false-position search (a refuted step or an unusable slope ends
    the steps).
    """
    prev = math.nan
    while hi - lo > tol:
        g = slopes.get(lo, math.nan)
        if not (math.isfinite(g) and g < 0 and math.isfinite(lo_s) and lo_s > 0):
            break
        step = lo_s / -g
        # remaining gain: the step, or the geometric tail of steps shrinking at the ratio
        # of the last two (a kinked strictness converges linearly)
        rate = min(step / prev, 0.9) if math.isfinite(prev) and prev > 0 else 0.0
        if step / (1.0 - rate) < 0.5 * tol:
            return True, lo, lo_s, hi, hi_s
        prev = step
        x = min(lo + step, hi - 0.5 * tol)
        sc, ok = trial(x)
        if ok is None:
            hi, hi_s = x, sc
            break
        lo, lo_s = x, sc
    return False, lo, lo_s, hi, hi_s


def _try(problem: Problem, h0: float, h1: float, **kw: Any) -> InputDelayResult | None:
    try:
        return synthesize_input_delay(problem, h0, h1, **kw)
    except (InfeasibleError, CertificateError, SolverFailure):
        return None


def max_certified_input_delay(problem: Problem, h_min: float = 0.0, *,
                              gain_bound: float | None = None, alpha: float = 0.0,
                              nominal: bool = False, state_delay: bool | None = None,
                              h_hi: float = 2.0, tol: float = 1e-3,
                              eps_grid: Sequence[float] = DEFAULT_EPS_GRID,
                              refine: int = DEFAULT_REFINE, margin: float = DEFAULT_MARGIN,
                              solver: str = DEFAULT_SOLVER) -> InputDelayResult:
    """Largest certified ``h_max`` for the given ``h_min``, by bisection (docstring step 7).

    Each trial stops at the first ``eps`` with a verified certificate, searching
    ``eps`` locally from the last success (:func:`.search.eps_search`); the result at
    the final ``h_max`` is the strictest point of an ``eps`` climb from there (with
    refinement; the whole grid if the climb finds nothing).  The
    returned ``h_max`` is within ``tol`` of the largest the LMI family certifies for
    the ``eps`` tried (a lower bound: ``eps`` is searched heuristically).  Returns the
    result at ``h_max`` (``result.h_max``); ``h_hi`` itself if it is certified.

    Parameters
    ----------
    problem : Problem
        Plant, perturbation and state delay.
    h_min : float, optional
        Low end of the latency interval (s).
    gain_bound : float, optional
        ``||K||_2`` bound.
    alpha : float, optional
        Decay rate the certificate must show (1/s).
    nominal : bool, optional
        Drop the ``E D F`` terms.
    state_delay : bool, optional
        Include ``A_tau`` (default: iff nonzero).
    h_hi : float, optional
        Largest ``h_max`` tried (s).
    tol : float, optional
        Absolute tolerance of ``h_max`` (s).
    eps_grid, refine, margin, solver
        As in :func:`synthesize_input_delay`.

    Returns
    -------
    InputDelayResult

    Raises
    ------
    InfeasibleError
        Not even ``h_max = h_min`` (or ``tol`` when ``h_min = 0``) is certified.
    """
    h0 = check_interval(h_min, max(float(h_min), tol))[0]
    if not (math.isfinite(h_hi) and h_hi > h0 and tol > 0):
        raise InputError(f'need h_hi > h_min and tol > 0, got h_hi={h_hi!r}, tol={tol!r}')
    kw: dict[str, Any] = dict(gain_bound=gain_bound, alpha=alpha, nominal=nominal,
                              state_delay=state_delay, eps_grid=eps_grid, refine=refine,
                              margin=margin, solver=solver)
    last: list[float] = []

    def trial(h1: float) -> InputDelayResult | None:
        r = _try(problem, h0, h1, **kw, stop_at_first=True,
                 eps_start=last[-1] if last else None)
        if r is not None:
            last.append(r.eps)
        return r

    lo = max(h0, tol)
    base = trial(lo)
    if base is None:
        raise InfeasibleError(f'{_describe(problem, h0, lo, alpha, nominal, gain_bound)} is '
                              'infeasible: no input delay interval is certified. Try a looser '
                              'gain bound, a smaller decay rate or a smaller F.')
    # doubling then bisection to the absolute tolerance ``tol``
    lo_h, hi_h = lo, None
    h = max(2 * lo, lo + tol)
    while True:
        h = min(h, h_hi)
        r = trial(h)
        if r is None:
            hi_h = h
            break
        lo_h = h
        if h >= h_hi:
            break
        h = 2 * h
    if hi_h is not None:
        while hi_h - lo_h > tol:
            mid = 0.5 * (lo_h + hi_h)
            if trial(mid) is None:
                hi_h = mid
            else:
                lo_h = mid
    full = _try(problem, h0, lo_h, eps_start=last[-1], **kw)
    if full is None:
        full = synthesize_input_delay(problem, h0, lo_h, eps=last[-1], **{
            k: v for k, v in kw.items() if k != 'eps_grid'})
    return full


class _DecaySearch:
    """The state of :func:`max_input_delay_decay_rate`'s search (see its docstring).

    ``lo``/``best`` is the largest certified rate and its result, ``hi`` the smallest
    refuted one (``inf``: none yet) with its score ``hi_s``; ``last`` the ``eps`` of every
    success, ``slopes`` ``dt/dalpha`` by rate (``_alpha_slope``).
    """

    def __init__(self, problem: Problem, h_min: float, h_max: float, kw: dict[str, Any],
                 margin: float, hi_limit: float, prog: _InputDelayProgram) -> None:
        self.problem, self.h_min, self.h_max, self.kw = problem, h_min, h_max, kw
        self.margin, self.hi_limit, self.prog = margin, hi_limit, prog
        self.slopes: dict[float, float] = {}
        self.last: list[float] = []
        self.refuted: list[float] = []
        self.lo, self.hi, self.hi_s = 0.0, math.nan, math.nan
        self.best: InputDelayResult

    def slope_of(self, a: float, r: InputDelayResult) -> None:
        """Record ``dt/dalpha`` at ``a`` if the program's last solve was ``r``'s point."""
        # the program's duals are those of ``r`` iff its last solve was ``r``'s point
        prog = self.prog
        key = prog._last[0] if prog._last is not None else None
        if key is not None and key[1:5] == (self.h_min, self.h_max, float(a), r.eps):
            self.slopes[a] = _alpha_slope(prog, self.h_min, self.h_max, a, self.problem.tau)

    def start(self, middle: float, refine: int) -> bool:
        """The first certified rate and the doubling to a bracket; ``True``: done (``best``).

        The first rate of the doubling first: when it is certified (the common case) it
        proves ``alpha = 0`` as well, one solve fewer.
        """
        problem, h_min, h_max, kw = self.problem, self.h_min, self.h_max, self.kw
        first = min(0.5, self.hi_limit)
        base = _try(problem, h_min, h_max, alpha=first, stop_at_first=True, refine=0,
                    eps_start=middle, **kw)
        if base is not None:
            if first >= self.hi_limit:
                self.best = base
                return True
            self.slope_of(first, base)
        else:
            first = 0.0
            base = _try(problem, h_min, h_max, alpha=0.0, stop_at_first=True, refine=refine,
                        eps_start=middle, **kw)
        if base is None:    # the whole grid (raises with the reason if nothing is certified)
            base = synthesize_input_delay(problem, h_min, h_max, alpha=0.0, refine=refine,
                                          **kw)
        self.last.append(base.eps)
        self.lo, self.best = first, base
        return self.double(2.0 * first if first else 0.5, newton_first=True)

    def trial(self, a: float, climb: bool = True) -> tuple[float, InputDelayResult | None]:
        """``(t - margin, result or None)`` at ``a``: a climb, or one solve at the last ``eps``."""
        problem, h_min, h_max, kw, last = self.problem, self.h_min, self.h_max, self.kw, self.last
        try:
            if climb:
                r = synthesize_input_delay(problem, h_min, h_max, alpha=a, stop_at_first=True,
                                           eps_start=last[-1], refine=0, **kw)
            else:
                r = synthesize_input_delay(problem, h_min, h_max, alpha=a, eps=last[-1],
                                           **{k: v for k, v in kw.items() if k != 'eps_grid'})
        except (InfeasibleError, CertificateError) as exc:
            return getattr(exc, 'margin_achieved', math.nan) - self.margin, None
        except SolverFailure:
            return math.nan, None
        last.append(r.eps)
        self.slope_of(a, r)
        return r.margin_achieved - self.margin, r

    def single(self, x: float) -> tuple[float, InputDelayResult | None]:
        """One solve at the ``eps`` of the last success; a refuted ``x`` is recorded."""
        sc, r = self.trial(x, climb=False)
        if r is None:
            self.refuted.append(x)
        return sc, r

    def newton_below(self, x: float, a: float) -> bool:
        """Newton from the certified rate ``x`` predicts the boundary below ``a``."""
        g, sx = self.slopes.get(x, math.nan), self.best.margin_achieved - self.margin
        return x > 0 and math.isfinite(g) and g < 0 and sx > 0 and x + sx / -g < a

    def double(self, a: float, newton_first: bool = False) -> bool:
        """Double the rate from ``a`` until one is refuted (``hi``); ``True``: ``hi_limit`` holds.

        One solve at the ``eps`` of the last success: a failing rate is not climbed here
        (the climb at the bracket's upper end checks the other ``eps``).  With
        ``newton_first``, a Newton step from ``lo`` predicting the boundary below ``a``
        ends the doubling without a bracket (``hi = inf``).
        """
        while True:
            if newton_first and self.newton_below(self.lo, a):
                self.hi = math.inf
                return False
            s, r = self.trial(a, climb=False)
            if r is None:
                self.hi, self.hi_s = a, s
                return False
            self.lo, self.best = a, r
            if a >= self.hi_limit:
                return True
            a = min(2.0 * a, self.hi_limit)

    def newton(self, tol: float) -> bool | None:
        """Newton steps from the certified end; ``True``: converged, ``None``: ``hi_limit``.

        Each step lands below the boundary while ``t(alpha)`` is convex there; a refuted
        step (``hi``) or an unusable slope hands over (``False``).
        """
        while self.hi - self.lo > tol:
            if self.lo >= self.hi_limit:
                return None
            g = self.slopes.get(self.lo, math.nan)
            s_lo = self.best.margin_achieved - self.margin
            if not (math.isfinite(g) and g < 0 and s_lo > 0):
                return False
            step = s_lo / -g
            if step < 0.25 * tol:
                return True
            x = min(self.lo + step, self.hi - 0.5 * tol, self.hi_limit)
            sc, r = self.single(x)
            if r is None:
                self.hi, self.hi_s = x, sc
                return False
            self.lo, self.best = x, r
        return False

    def climb_above(self) -> bool:
        """Another ``eps`` certifies ``hi``: brackets above it; ``True``: ``hi_limit`` reached."""
        while True:
            if self.lo >= self.hi_limit:
                return True
            self.hi = min(2.0 * self.lo, self.hi_limit)
            self.hi_s, r = self.trial(self.hi)
            if r is None:
                return False
            self.lo, self.best = self.hi, r

    def close(self, rel_tol: float) -> InputDelayResult:
        """Close the bracket to ``rel_tol``, then check it with a climb (docstring).

        Inside the bracket the ``eps`` of the last success is kept (one solve per trial:
        the climb at ``hi`` found it a local maximum of the grid, and the best ``eps``
        moves slowly with ``alpha``); once closed, one climb at ``hi`` checks that no other
        ``eps`` certifies it.
        """
        for _ in range(4):
            self.refuted = [self.hi]
            # without a refuted rate yet (hi = inf) the tolerance is that of the doubling's
            # next bracket [lo, 2 lo]
            tol = rel_tol * (self.hi if math.isfinite(self.hi)
                             else min(2.0 * self.lo, self.hi_limit))
            newton = self.newton(tol)
            if newton is None:
                return self.best
            if newton:
                top = min(self.lo + tol, self.hi)
            elif not math.isfinite(self.hi):
                # Newton gave out before any rate was refuted: doubling from lo, as above
                if self.double(min(2.0 * self.lo, self.hi_limit)):
                    return self.best
                continue
            else:
                # the first step halves the bracket: the strictness at the low end is often
                # capped by the normalization (t <= 1 with a gain bound): it would skew the
                # secant
                self.lo, self.best, _ = largest_feasible_bracketed(
                    self.single, self.lo, self.hi, self.best, tol=tol, lo_score=math.nan,
                    hi_score=self.hi_s)
                top = self.hi = min(self.refuted)
            _, r = self.trial(top)
            if r is None:
                break
            self.lo, self.best = top, r
            if newton and top < self.hi:     # certified by another eps: on from there
                continue
            if self.climb_above():
                return self.best
        return self.best


def max_input_delay_decay_rate(problem: Problem, h_min: float, h_max: float, *,
                               gain_bound: float | None = None, nominal: bool = False,
                               state_delay: bool | None = None, rel_tol: float = 2e-3,
                               hi_limit: float = 50.0,
                               eps_grid: Sequence[float] = DEFAULT_EPS_GRID,
                               refine: int = DEFAULT_REFINE, margin: float = DEFAULT_MARGIN,
                               solver: str = DEFAULT_SOLVER) -> InputDelayResult:
    """Largest certified decay rate ``alpha`` for input delays in ``[h_min, h_max]``.

    ``alpha = 0.5`` first, by a climb on the ``eps`` grid from its middle stopping at the
    first verified point (certified, it proves ``alpha = 0`` too; if not, ``alpha = 0``
    decides feasibility the same way, the whole grid if the climb finds none), then
    doubling until a rate fails or a Newton step from the last certified rate predicts
    the boundary below the next doubling, each trial one solve at the ``eps`` of the last
    success (a failing rate is not climbed: the climb at the end checks the other
    ``eps``); then
    Newton steps on the strictness ``t(alpha) - margin`` from the certified end, with the
    slope ``dt/dalpha`` read from the dual of the same solve (``_alpha_slope``,
    envelope theorem), until the next step would gain less than a quarter of the
    tolerance ``rel_tol * hi``; a step that is refuted hands the bracket to false position
    (:func:`.search.largest_feasible_bracketed`); finally one climb just above the result
    (at the refuted end, or ``tol`` above the last Newton point) checks that no other
    ``eps`` certifies it (if one does, the search goes on above).  A repeated point
    (same data, rate and ``eps``) is not solved again (the solver is deterministic).

    Why this search (measured on the paper problem, ``||K|| <= 8.67``, ``[0, 0.08]`` and
    ``[0, 0.2]`` s): each SDP costs 60-130 ms inside the solver on an idle core and a
    cached DPP program is re-solved without recompiling (:func:`.sdp.cached_program`),
    so the time is the number of solves.  Halving the ``alpha`` bracket to 1 % took 7-8
    trials, and every failing trial climbed the ``eps`` grid and refined it by golden
    section (and a point rejected by the numpy check scanned the whole grid): 99 and 164
    solves.  ``t(alpha)`` at the best ``eps`` is smooth and convex on the feasible side
    (its slope rises from -2.2 at 0.5 1/s to -0.26 just below the boundary on
    ``[0, 0.2]`` s, and it is kinked at the boundary), and the best ``eps`` moves slowly
    with ``alpha`` (0.32 on both intervals).  False position closed a ``rel_tol`` 0.2 %
    bracket in 14 and 17 solves (1.511 and 0.716 1/s); the Newton steps, which for a
    convex ``t`` stay on the certified side, take 9 and 8 solves, with 1.5111 and
    0.7167 1/s.  A generalized-eigenvalue formulation was not used: ``alpha`` enters
    through the ``exp(-2 alpha h)`` weights as well as ``2 alpha P``, so the problem is
    not a GEVP in ``alpha`` (and cvxpy has no GEVP solver: it would be bisected over SDPs
    all the same).  Solver tolerances are unchanged.

    Feasibility is not proven monotone in ``alpha``, so the result is a verified lower
    bound of the best rate (the point the last successful trial verified).

    Parameters
    ----------
    problem : Problem
        Plant, perturbation and state delay.
    h_min, h_max : float
        Latency interval (s).
    gain_bound : float, optional
        ``||K||_2`` bound.
    nominal : bool
        Drop the ``E D F`` terms.
    state_delay : bool, optional
        Include ``A_tau`` (default: iff nonzero).
    rel_tol : float
        Relative width of the final ``alpha`` bracket.
    hi_limit : float
        Largest rate tried (returned as is if certified).
    eps_grid, refine, margin, solver
        As in :func:`synthesize_input_delay` (``refine`` is used by the ``alpha = 0``
        feasibility scan only).

    Raises
    ------
    InfeasibleError
        Not even ``alpha = 0`` is certified.
    """
    kw: dict[str, Any] = dict(gain_bound=gain_bound, nominal=nominal,
                              state_delay=state_delay, eps_grid=eps_grid, margin=margin,
                              solver=solver)
    grid = sorted(float(e) for e in eps_grid)
    prog = _program(problem, nominal, gain_bound is not None,
                    _uses_state_delay(problem, state_delay))
    search = _DecaySearch(problem, float(h_min), float(h_max), kw, margin, float(hi_limit),
                          prog)
    if search.start(grid[len(grid) // 2], refine):
        return search.best
    return search.close(rel_tol)
