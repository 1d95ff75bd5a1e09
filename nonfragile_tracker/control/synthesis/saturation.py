"""A region of attraction of the tracker on the robot: its clamps, its speed premise, Delta.

The tracker applies ``u = u_d + (K + E Delta F) e`` through its own clamps (tangential
acceleration, turn rate).  A generalized sector condition with a scalar multiplier (it holds
at every heading), a delay-independent Krasovskii functional and Petersen's lemma for
``||Delta|| <= 1`` give one SDP that certifies an ellipsoid of constant initial histories;
the speed premise is kept inside it (``V`` searched or given), and two solves maximize the
position radius.  Command latency and actuator lag are not covered (the scope is printed,
:meth:`SaturationCertificate.model`); a refusal names the failed premise.  The certificate
is checked independently in numpy (:func:`verify_saturation`).

See doc/theory.md, section "Saturation: a certified region of attraction"
(#saturation-a-certified-region-of-attraction), and its "Derivation".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import InputError
from .certificate import eigen_figures, passes
from .sdp import sym

__all__ = ['SaturationLimits', 'SaturationCertificate', 'saturation_certificate',
           'verify_saturation', 'format_saturation', 'premise_failure']

#: Shrinks of the solver's ellipsoid tried until the numpy check passes (solver accuracy).
_SHRINKS = (1.0, 1 + 1e-9, 1 + 1e-7, 1 + 1e-5, 1 + 1e-3)
#: Speeds ``V`` tried by the search (the grid; a golden-section refinement follows).
_GRID = 7
_REFINE = 6


@dataclass(frozen=True)
class SaturationLimits:
    """The tracker's limits and the premises of the certificate (SI units).

    Parameters
    ----------
    max_angular_speed : float
        The tracker's ``|w|`` clamp (rad/s).
    min_speed : float
        ``V``: the smallest ``|v|`` kept along every certified trajectory (m/s); 0 = search
        the ``V`` with the largest radius in ``[speed_floor, cruise_speed)``.
    max_linear_accel : float
        The tracker's ``|dv/dt|`` clamp (m/s^2); 0 = none (only the turn rate bounds ``u``).
    max_reference_accel : float
        ``||u_d||`` of the reference the tracker follows (m/s^2, Euclidean norm).
    cruise_speed : float
        The smallest speed of the reference the tracker follows (m/s); 0 = not given (no
        claim: the speed premise cannot be kept).
    speed_floor : float
        The tracker's ``min_speed`` (m/s): below it the tracker floors ``v`` in ``w = u_n /
        v``, which the sector condition does not cover, so ``V >= speed_floor``.
    max_linear_speed : float
        The tracker's ``|v|`` clamp (m/s); 0 = not checked.  The reference speed plus the
        certified speed error must stay below it.
    max_reference_speed : float
        The largest speed of the reference (m/s); 0 = ``cruise_speed``.
    """

    max_angular_speed: float
    min_speed: float = 0.0
    max_linear_accel: float = 0.0
    max_reference_accel: float = 0.0
    cruise_speed: float = 0.0
    speed_floor: float = 1e-3
    max_linear_speed: float = 0.0
    max_reference_speed: float = 0.0

    def __post_init__(self) -> None:
        v = self.max_angular_speed
        if not (math.isfinite(v) and v > 0):
            raise InputError(f'max_angular_speed must be a finite number > 0, got {v!r}')
        for name in ('min_speed', 'max_linear_accel', 'max_reference_accel', 'cruise_speed',
                     'speed_floor', 'max_linear_speed', 'max_reference_speed'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f'{name} must be a finite number >= 0, got {v!r}')

    @property
    def u_max(self) -> float:
        """Saturation level of ``||u||`` below which no clamp binds at ``|v| >= V`` (m/s^2)."""
        u = self.min_speed * self.max_angular_speed
        return min(u, self.max_linear_accel) if self.max_linear_accel > 0 else u

    @property
    def level(self) -> float:
        """Dead-zone level of the feedback part (m/s^2): ``u_max - d``."""
        return self.u_max - self.max_reference_accel

    @property
    def speed_error(self) -> float:
        """The velocity-error bound that keeps ``|v| >= V`` (m/s): ``cruise - V``."""
        return self.cruise_speed - self.min_speed


def premise_failure(limits: SaturationLimits) -> str:
    """The premise of the certificate that cannot hold with these limits ('' if none).

    Parameters
    ----------
    limits : SaturationLimits
        With the ``V`` (``min_speed``) to check (> 0).

    Returns
    -------
    str
        The failed premise, named, with what to change; '' when every premise can hold.
    """
    lim = limits
    if lim.cruise_speed <= 0:
        return ('speed premise |v| >= V: no cruise speed given (the smallest speed of the '
                'reference the tracker follows, --cruise-speed); without it no speed error '
                'bound keeps the turn-rate limit inside the model')
    if lim.min_speed < lim.speed_floor:
        return (f'speed floor: V = {lim.min_speed:g} m/s is below the tracker\'s min_speed '
                f'{lim.speed_floor:g} m/s (there the tracker floors v in w = u_n / v, which the '
                'sector condition does not cover)')
    if lim.speed_error <= 0:
        return (f'speed premise |v| >= V: the cruise speed {lim.cruise_speed:g} m/s is not above '
                f'V = {lim.min_speed:g} m/s, so no velocity error keeps |v| >= V')
    if lim.level <= 0:
        return (f'input headroom: the reference acceleration {lim.max_reference_accel:g} m/s^2 '
                f'uses the whole saturation level {lim.u_max:.4g} m/s^2 (min(|dv/dt| limit, '
                f'V |w| limit) at V = {lim.min_speed:g} m/s)')
    top = (lim.max_reference_speed or lim.cruise_speed) + lim.speed_error
    if lim.max_linear_speed > 0 and top > lim.max_linear_speed:
        return (f'speed limit: the reference speed plus the speed error ({top:.4g} m/s) exceeds '
                f'the tracker\'s max_linear_speed {lim.max_linear_speed:g} m/s')
    return ''


@dataclass(frozen=True)
class SaturationCertificate:
    """The certified set ``e0' (P + tau Q) e0 <= 1`` and what it means (or the refusal).

    ``radius`` is the largest initial position error (zero velocity error) in the set;
    ``radius_first`` the same figure of the first solve's point (the SDP that bounds
    ``E(P, 1)`` only); ``refusal`` names the premise that fails ('' when certified).
    """

    limits: SaturationLimits
    P: np.ndarray
    Q: np.ndarray
    G: np.ndarray
    t: float                     # the sector multiplier T = t I
    eps: float                   # Petersen scalar of the decrease LMI (0: no Delta)
    mu: float                    # Petersen scalar of the inclusion (0: no Delta)
    tau: float
    delta: bool                  # ||Delta|| <= 1 through E, F covered
    radius: float                # largest certified initial position error (m)
    radius_first: float          # the first solve's figure (m)
    max_eig: float               # numpy check of the decrease LMI (< 0)
    inclusion_eig: float         # smallest eigenvalue of the inclusion LMI (>= 0)
    speed_bound: float           # max ||e_v|| over E(P, 1) (<= cruise - V)
    status: str
    refusal: str = ''

    @property
    def verified(self) -> bool:
        """Certified: a premise-checked point that passes the numpy check."""
        return (not self.refusal and self.max_eig < 0 and self.inclusion_eig >= 0
                and self.speed_bound <= self.limits.speed_error * (1 + 1e-9)
                and self.radius > 0)

    def contains(self, e0: Any) -> bool:
        """A constant initial history ``e0`` (error state) is inside the certified set.

        Parameters
        ----------
        e0 : array_like, shape (n,)
            The error state.

        Returns
        -------
        bool
        """
        e0 = np.asarray(e0, float)
        return float(e0 @ (self.P + self.tau * self.Q) @ e0) <= 1.0

    def model(self) -> str:
        """One line: which gain, which saturation, which delay, which initial set."""
        lim = self.limits
        acc = (f'|dv/dt| <= {lim.max_linear_accel:g} m/s^2 and ' if lim.max_linear_accel
               else '')
        return ('model: gain K' + (' + E Delta F, ||Delta|| <= 1' if self.delta else
                                      ' (nominal: no Delta)')
                + f'; saturation: the tracker\'s separate clamps {acc}|w| <= '
                f'{lim.max_angular_speed:g} rad/s at |v| >= V = {lim.min_speed:.4g} m/s (kept: '
                f'||e_v|| <= {lim.speed_error:.4g} m/s below the cruise speed '
                f'{lim.cruise_speed:g} m/s), any heading; reference acceleration <= '
                f'{lim.max_reference_accel:g} m/s^2; delay: constant state delay tau = '
                f'{self.tau:g} s (delay-independent'
                + ('; the tracker follows the delay-consistent reference' if self.tau > 0
                   else '') + '), NO command latency, NO actuator lag; '
                'initial set: constant history e0 with e0\'(P + tau Q) e0 <= 1')


def _selectors(n: int) -> tuple[np.ndarray, np.ndarray]:
    # xi = [x, x', y, y', ...]: positions are the even coordinates, velocities the odd ones
    C = np.zeros((n // 2, n))
    Cv = np.zeros((n // 2, n))
    for i in range(n // 2):
        C[i, 2 * i] = 1.0
        Cv[i, 2 * i + 1] = 1.0
    return C, Cv


def _refused(limits: SaturationLimits, n: int, m: int, tau: float, delta: bool,
             why: str, status: str = 'refused') -> SaturationCertificate:
    z = np.zeros((n, n))
    return SaturationCertificate(limits, z, z, np.zeros((m, n)), 0.0, 0.0, 0.0, float(tau),
                                 delta, 0.0, 0.0, math.inf, -math.inf, math.inf, status, why)


def _first_solve(Acl: np.ndarray, B: np.ndarray, K: np.ndarray, Ad: np.ndarray,
                 E: np.ndarray | None, F: np.ndarray | None, slab: float, solver: str,
                 margin: float) -> tuple[str, dict[str, Any] | None]:
    """The ``W``-form SDP at unit level: min ``beta`` with ``C W^-1 C' <= beta I``."""
    import cvxpy as cp

    from .sdp import solve
    n, m = B.shape
    C, Cv = _selectors(n)
    W = cp.Variable((n, n), symmetric=True)
    R = cp.Variable((n, n), symmetric=True)
    Z = cp.Variable((m, n))
    s = cp.Variable()
    beta = cp.Variable()
    top = Acl @ W + W @ Acl.T + R
    cons = [W >> margin * np.eye(n), R >> margin * np.eye(n), s >= margin]
    incl = [[W, W @ K.T - Z.T], [K @ W - Z, np.eye(m)]]
    eps: Any
    mu: Any
    if E is not None and F is not None:
        eps = cp.Variable()
        mu = cp.Variable()
        q, r = E.shape[1], F.shape[0]
        BE = B @ E
        top = top + eps * (BE @ BE.T)
        M = cp.bmat([[top, Ad @ W, -s * B + Z.T, W @ F.T],
                     [W @ Ad.T, -R, np.zeros((n, m)), np.zeros((n, r))],
                     [-s * B.T + Z, np.zeros((m, n)), -2 * s * np.eye(m), np.zeros((m, r))],
                     [F @ W, np.zeros((r, n)), np.zeros((r, m)), -eps * np.eye(r)]])
        incl = [[W, W @ K.T - Z.T, W @ F.T],
                [K @ W - Z, np.eye(m) - mu * (E @ E.T), np.zeros((m, r))],
                [F @ W, np.zeros((r, m)), mu * np.eye(r)]]
        cons += [eps >= margin, mu >= margin]
        del q
    else:
        eps = mu = None
        M = cp.bmat([[top, Ad @ W, -s * B + Z.T],
                     [W @ Ad.T, -R, np.zeros((n, m))],
                     [-s * B.T + Z, np.zeros((m, n)), -2 * s * np.eye(m)]])
    k = M.shape[0]
    Mi = cp.bmat(incl)
    Mb = cp.bmat([[beta * np.eye(n // 2), C], [C.T, W]])
    Ms = Cv @ W @ Cv.T
    cons += [0.5 * (M + M.T) << -margin * np.eye(k), 0.5 * (Mi + Mi.T) >> 0,
             0.5 * (Mb + Mb.T) >> 0, 0.5 * (Ms + Ms.T) << slab ** 2 * np.eye(n // 2)]
    out = solve(cp.Problem(cp.Minimize(beta), cons), solver,
                what='the saturation region LMI (W-form)', quiet_inaccurate=True)
    if W.value is None or s.value is None:
        return out.status, None
    Wv = 0.5 * (W.value + W.value.T)
    P = np.linalg.inv(Wv)
    P = 0.5 * (P + P.T)
    Rs = np.asarray(R.value, float)
    Rv = 0.5 * (Rs + Rs.T)
    Qv = P @ Rv @ P
    point = {'P': P, 'Q': 0.5 * (Qv + Qv.T), 'G': np.asarray(Z.value, float) @ P,
             't': 1.0 / float(s.value),
             'eps': 1.0 / float(eps.value) if eps is not None and eps.value else 0.0,
             'mu': float(mu.value) if mu is not None and mu.value is not None else 0.0}
    return out.status, point


def _second_solve(Acl: np.ndarray, B: np.ndarray, K: np.ndarray, Ad: np.ndarray, tau: float,
                  E: np.ndarray | None, F: np.ndarray | None, slab: float, t: float,
                  solver: str, margin: float) -> tuple[str, dict[str, Any] | None]:
    """The ``P``-form SDP at unit level, ``T = t I`` fixed: min ``C (P + tau Q) C' <= beta``."""
    import cvxpy as cp

    from .sdp import solve
    n, m = B.shape
    C, Cv = _selectors(n)
    P = cp.Variable((n, n), symmetric=True)
    Q = cp.Variable((n, n), symmetric=True)
    Gt = cp.Variable((m, n))            # t G
    beta = cp.Variable()
    top = Acl.T @ P + P @ Acl + Q
    cons = [P >> margin * np.eye(n), Q >> margin * np.eye(n)]
    G = Gt / t
    incl = [[P, K.T - G.T], [K - G, np.eye(m)]]
    eps: Any
    mu: Any
    if E is not None and F is not None:
        eps = cp.Variable()
        mu = cp.Variable()
        q, r = E.shape[1], F.shape[0]
        M = cp.bmat([[top + eps * (F.T @ F), P @ Ad, -P @ B + Gt.T, P @ B @ E],
                     [Ad.T @ P, -Q, np.zeros((n, m)), np.zeros((n, q))],
                     [-B.T @ P + Gt, np.zeros((m, n)), -2 * t * np.eye(m), np.zeros((m, q))],
                     [E.T @ B.T @ P, np.zeros((q, n)), np.zeros((q, m)), -eps * np.eye(q)]])
        incl = [[P, K.T - G.T, F.T],
                [K - G, np.eye(m) - mu * (E @ E.T), np.zeros((m, r))],
                [F, np.zeros((r, m)), mu * np.eye(r)]]
        cons += [eps >= margin, mu >= margin]
    else:
        eps = mu = None
        M = cp.bmat([[top, P @ Ad, -P @ B + Gt.T],
                     [Ad.T @ P, -Q, np.zeros((n, m))],
                     [-B.T @ P + Gt, np.zeros((m, n)), -2 * t * np.eye(m)]])
    k = M.shape[0]
    Mi = cp.bmat(incl)
    Ms = cp.bmat([[P, Cv.T], [Cv, slab ** 2 * np.eye(n // 2)]])
    Mo = C @ (P + tau * Q) @ C.T
    cons += [0.5 * (M + M.T) << -margin * np.eye(k), 0.5 * (Mi + Mi.T) >> 0,
             0.5 * (Ms + Ms.T) >> 0, 0.5 * (Mo + Mo.T) << beta * np.eye(n // 2)]
    out = solve(cp.Problem(cp.Minimize(beta), cons), solver,
                what='the saturation region LMI (P-form)', quiet_inaccurate=True)
    if P.value is None or Q.value is None or Gt.value is None:
        return out.status, None
    point = {'P': 0.5 * (P.value + P.value.T), 'Q': 0.5 * (Q.value + Q.value.T),
             'G': np.asarray(Gt.value, float) / t, 't': t,
             'eps': float(eps.value) if eps is not None and eps.value is not None else 0.0,
             'mu': float(mu.value) if mu is not None and mu.value is not None else 0.0}
    return out.status, point


def _checked(A: np.ndarray, B: np.ndarray, K: np.ndarray, Ad: np.ndarray, tau: float,
             limits: SaturationLimits, point: dict[str, Any], E: np.ndarray | None,
             F: np.ndarray | None, status: str) -> SaturationCertificate:
    """A unit-level point in the limits' units, shrunk until the numpy check passes."""
    lev = limits.level
    best = None
    for c in _SHRINKS:
        cert = verify_saturation(A, B, K, Ad, tau, limits, c * point['P'] / lev ** 2,
                                 c * point['Q'] / lev ** 2, point['G'],
                                 c * point['t'] / lev ** 2, E=E, F=F,
                                 eps=c * point['eps'] / lev ** 2, mu=point['mu'] * lev ** 2,
                                 status=status)
        best = cert if best is None else best
        if cert.verified:
            return cert
    assert best is not None
    return best


def _at_speed(A: np.ndarray, B: np.ndarray, K: np.ndarray, Ad: np.ndarray, tau: float,
              limits: SaturationLimits, E: np.ndarray | None, F: np.ndarray | None,
              solver: str, margin: float) -> SaturationCertificate:
    """The certificate at the ``V`` of ``limits`` (two solves)."""
    n, m = B.shape
    delta = E is not None
    why = premise_failure(limits)
    if why:
        return _refused(limits, n, m, tau, delta, why)
    Acl = A + B @ K
    slab = limits.speed_error / limits.level
    status, first = _first_solve(Acl, B, K, Ad, E, F, slab, solver, margin)
    if first is None:
        return _refused(limits, n, m, tau, delta,
                        f'the LMI has no solution at V = {limits.min_speed:.4g} m/s '
                        f'(solver: {status})', status)
    one = _checked(A, B, K, Ad, tau, limits, first, E, F, status)
    status2, second = _second_solve(Acl, B, K, Ad, tau, E, F, slab, first['t'], solver, margin)
    two = _checked(A, B, K, Ad, tau, limits, second, E, F, status2) if second else None
    best = two if two is not None and two.verified and two.radius >= one.radius else one
    return replace(best, radius_first=one.radius if one.verified else 0.0)


def saturation_certificate(A: Any, B: Any, K: Any, A_tau: Any, tau: float,
                           limits: SaturationLimits, *, E: Any = None, F: Any = None,
                           solver: str = 'CLARABEL', margin: float = 1e-7
                           ) -> SaturationCertificate:
    """Largest certified initial position error of the tracker under its clamps (module text).

    Parameters
    ----------
    A, B, K, A_tau : array_like
        The linearized robot (``n x n``, ``n x m``), the gain (``m x n``) and the delay
        matrix; positions are the even coordinates of ``xi`` (``[x, x', y, y']``), velocities
        the odd ones.
    tau : float
        The state delay (s).
    limits : SaturationLimits
        The tracker's clamps, the cruise speed and the reference acceleration; ``min_speed``
        0 searches ``V``.
    E, F : array_like, optional
        The gain perturbation ``E Delta F`` (``||Delta|| <= 1``, time-varying allowed); None:
        the nominal gain only (said in :meth:`SaturationCertificate.model`).
    solver : str
        cvxpy solver.
    margin : float
        Strictness of the LMIs.

    Returns
    -------
    SaturationCertificate
        ``refusal`` naming the failed premise (and ``radius`` 0) when nothing is certified.
    """
    A, B, K, Ad = (np.asarray(M, float) for M in (A, B, K, A_tau))
    Ea = None if E is None else np.asarray(E, float)
    Fa = None if F is None else np.asarray(F, float)
    if (Ea is None) != (Fa is None):
        raise InputError('give both E and F (the perturbation E Delta F) or neither')
    if limits.min_speed > 0:
        return _at_speed(A, B, K, Ad, tau, limits, Ea, Fa, solver, margin)
    lo = max(limits.speed_floor, 1e-9)
    if limits.max_reference_accel > 0:
        lo = max(lo, 1.0001 * limits.max_reference_accel / limits.max_angular_speed)
    hi = limits.cruise_speed
    first = _at_speed(A, B, K, Ad, tau, replace(limits, min_speed=lo), Ea, Fa, solver, margin)
    if first.refusal and (limits.cruise_speed <= 0 or lo >= hi):
        return first
    results = {lo: first}

    def at(v: float) -> float:
        if v not in results:
            results[v] = _at_speed(A, B, K, Ad, tau, replace(limits, min_speed=v), Ea, Fa,
                                   solver, margin)
        return results[v].radius

    grid = [lo + (hi - lo) * i / _GRID for i in range(_GRID)]
    vals = [at(v) for v in grid]
    i = int(np.argmax(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, _GRID - 1)] if i + 1 < _GRID else hi
    g = (math.sqrt(5) - 1) / 2
    for _ in range(_REFINE):
        x1, x2 = b - g * (b - a), a + g * (b - a)
        if at(x1) >= at(x2):
            b = x2
        else:
            a = x1
    best = max(results.values(), key=lambda c: (c.verified, c.radius))
    return best


def verify_saturation(A: Any, B: Any, K: Any, A_tau: Any, tau: float, limits: SaturationLimits,
                      P: Any, Q: Any, G: Any, t: float, *, E: Any = None, F: Any = None,
                      eps: float = 0.0, mu: float = 0.0,
                      status: str = 'given') -> SaturationCertificate:
    """Check a saturation certificate in numpy and compute its radius.

    Parameters
    ----------
    A, B, K, A_tau : array_like
        The loop.
    tau : float
        The delay (s).
    limits : SaturationLimits
        The limits (level ``l = u_max - d``, speed error ``cruise - V``).
    P, Q, G : array_like
        Lyapunov-Krasovskii matrices and the sector matrix ``G``.
    t : float
        The sector multiplier ``T = t I``.
    E, F : array_like, optional
        The perturbation (None: nominal).
    eps, mu : float
        Petersen scalars of the decrease and the inclusion LMIs (with ``E``, ``F``).
    status : str
        Where the point came from.

    Returns
    -------
    SaturationCertificate
        With ``max_eig`` of the decrease LMI ``[[Acl'P + P Acl + Q + eps F'F, P A_tau, -P B
        + t G', P B E], [*, -Q, 0, 0], [*, *, -2 t I, 0], [*, *, *, -eps I]]``, the smallest
        eigenvalue of the inclusion LMI ``[[P, (K - G)', F'], [*, l^2 I - mu E E', 0], [*, *,
        mu I]]``, the speed bound ``max ||e_v||`` over ``E(P, 1)``; ``radius`` 0 unless all
        pass.
    """
    A, B, K, Ad, P, Q, G = (np.asarray(M, float) for M in (A, B, K, A_tau, P, Q, G))
    n, m = B.shape
    Acl = A + B @ K
    delta = E is not None and F is not None
    lev = limits.level
    top = Acl.T @ P + P @ Acl + Q
    if delta:
        Ea, Fa = np.asarray(E, float), np.asarray(F, float)
        q, r = Ea.shape[1], Fa.shape[0]
        L = np.block([[top + eps * Fa.T @ Fa, P @ Ad, -P @ B + t * G.T, P @ B @ Ea],
                      [Ad.T @ P, -Q, np.zeros((n, m)), np.zeros((n, q))],
                      [-B.T @ P + t * G, np.zeros((m, n)), -2 * t * np.eye(m), np.zeros((m, q))],
                      [Ea.T @ B.T @ P, np.zeros((q, n)), np.zeros((q, m)), -eps * np.eye(q)]])
        Mi = np.block([[P, (K - G).T, Fa.T],
                       [K - G, lev ** 2 * np.eye(m) - mu * Ea @ Ea.T, np.zeros((m, r))],
                       [Fa, np.zeros((r, m)), mu * np.eye(r)]])
    else:
        L = np.block([[top, P @ Ad, -P @ B + t * G.T],
                      [Ad.T @ P, -Q, np.zeros((n, m))],
                      [-B.T @ P + t * G, np.zeros((m, n)), -2 * t * np.eye(m)]])
        Mi = np.block([[P, (K - G).T], [K - G, lev ** 2 * np.eye(m)]])
    max_eig, scale, mins = eigen_figures(sym(L), (P, Q))
    ok = passes(max_eig, scale, mins, (min(eps, mu) if delta else 1.0), 0.0) and t > 0
    incl = float(np.linalg.eigvalsh(sym(Mi))[0]) if np.all(np.isfinite(Mi)) else -math.inf
    C, Cv = _selectors(n)
    try:
        Pinv = np.linalg.inv(P)
        speed = math.sqrt(max(float(np.linalg.eigvalsh(sym(Cv @ Pinv @ Cv.T))[-1]), 0.0))
    except np.linalg.LinAlgError:
        speed = math.inf
    lam = float(np.linalg.eigvalsh(sym(C @ (P + tau * Q) @ C.T))[-1])
    good = (ok and incl >= 0 and lev > 0 and lam > 0
            and speed <= limits.speed_error * (1 + 1e-9))
    radius = 1.0 / math.sqrt(lam) if good else 0.0
    return SaturationCertificate(limits, P, Q, G, float(t), float(eps), float(mu), float(tau),
                                 delta, radius, radius, max_eig, incl, speed, status)


def format_saturation(cert: SaturationCertificate) -> str:
    """A few lines: the model, the certified radius (or the refusal) and the numpy check.

    Parameters
    ----------
    cert : SaturationCertificate
        The certificate.

    Returns
    -------
    str
    """
    lim = cert.limits
    head = 'saturation region of attraction (generalized sector condition)'
    if cert.refusal or not cert.verified:
        why = cert.refusal or f'the numpy check failed ({cert.status})'
        return f'{head}: NO radius certified: {why}'
    return (f'{head}\n  {cert.model()}\n  certified: every initial position error up to '
            f'{cert.radius * 1e3:.4g} mm (zero velocity error) converges, |v| >= '
            f'{lim.min_speed:.4g} m/s all along (first solve: {cert.radius_first * 1e3:.4g} mm)'
            f'\n  numpy check: max eig {cert.max_eig:.3g} < 0, inclusion min eig '
            f'{cert.inclusion_eig:.3g} >= 0, max ||e_v|| {cert.speed_bound * 1e3:.4g} <= '
            f'{lim.speed_error * 1e3:.4g} mm/s')
