"""A region of attraction of the tracking loop with saturating inputs.

The law commands ``u = u_d + K e`` (``e = xi - xi_d``, ``u`` the acceleration of the
linearized robot, ``u_d`` the reference acceleration).  The base's turn-rate and
acceleration limits hold while each world-frame component of ``u`` stays in a box; the
certified loop saturates ``u`` to that box::

    e' = A e + B (sat(u_d + K e) - u_d) + A_tau e(t - tau),   ||u_d||_inf <= d.

The generalized sector condition (Tarbouriech, Garcia, Gomes da Silva and Queinnec, 2011,
Lemma 1.6) and a delay-independent Krasovskii functional give two LMIs whose solution
certifies that every constant initial history in an ellipsoid converges; the program
maximizes the largest initial *position* error in it, and the radius scales with the
dead-zone level, which gives the largest reference acceleration for a wanted radius.

The box model, the LMIs (in ``W = P^-1``, ``Z = G W``, ``S = T^-1``, ``R = W Q W``), the
radius and the assumptions are in the documentation: doc/theory.md, section "Saturation: a
certified region of attraction" (#saturation-a-certified-region-of-attraction).

The certificate is checked independently in numpy (:func:`verify_saturation`): the
eigenvalues of the first LMI in the ``P``-form and the inclusion, from the solver's point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ...errors import InputError
from .certificate import eigen_figures, passes
from .sdp import sym

__all__ = ['SaturationLimits', 'SaturationCertificate', 'saturation_certificate',
           'verify_saturation', 'simulate_saturated', 'format_saturation', 'SimulationCheck',
           'check_by_simulation']


@dataclass(frozen=True)
class SaturationLimits:
    """The base's limits the certificate uses (SI units).

    Parameters
    ----------
    max_angular_speed : float
        ``|w|`` limit (rad/s).
    min_speed : float
        Smallest ``|v|`` along the motion (m/s), e.g. the reference's cruise speed minus
        the certified speed error.
    max_linear_accel : float
        ``|dv/dt|`` limit (m/s^2); 0 = unknown (only the turn rate bounds ``u``).
    max_reference_accel : float
        ``||u_d||_inf`` of the reference (m/s^2).
    """

    max_angular_speed: float
    min_speed: float
    max_linear_accel: float = 0.0
    max_reference_accel: float = 0.0

    def __post_init__(self) -> None:
        for name in ('max_angular_speed', 'min_speed'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InputError(f'{name} must be a finite number > 0, got {v!r}')
        for name in ('max_linear_accel', 'max_reference_accel'):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f'{name} must be a finite number >= 0, got {v!r}')

    @property
    def u_max(self) -> float:
        """``||u||`` below which neither limit is reached (m/s^2)."""
        u = self.min_speed * self.max_angular_speed
        return min(u, self.max_linear_accel) if self.max_linear_accel > 0 else u

    @property
    def box(self) -> float:
        """Per-component bound of ``u`` in the world frame (m/s^2)."""
        return self.u_max / math.sqrt(2.0)

    @property
    def level(self) -> float:
        """Dead-zone level of the feedback part ``K e`` (m/s^2): ``box - d``."""
        return self.box - self.max_reference_accel


@dataclass(frozen=True)
class SaturationCertificate:
    """The certified region (``P``, ``Q``) and what it means."""

    limits: SaturationLimits
    P: np.ndarray
    Q: np.ndarray
    G: np.ndarray
    T: np.ndarray
    tau: float
    radius: float               # largest certified initial position error (m)
    radius_per_level: float     # radius per m/s^2 of dead-zone level
    max_eig: float              # numpy check of the first LMI (< 0)
    inclusion: float            # max_i (K-G)_i P^-1 (K-G)_i' / l^2 (<= 1)
    status: str

    @property
    def verified(self) -> bool:
        """The numpy check of the solver's point passes."""
        return self.max_eig < 0 and self.inclusion <= 1 + 1e-9 and self.radius > 0

    def max_reference_accel(self, radius: float) -> float:
        """Largest ``||u_d||_inf`` (m/s^2) for which a position error ``radius`` is certified.

        Parameters
        ----------
        radius : float
            The initial position error to certify (m).

        Returns
        -------
        float
            In m/s^2 (negative: not even with zero reference acceleration).
        """
        return self.limits.box - radius / self.radius_per_level

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


def _position_selector(n: int) -> np.ndarray:
    # xi = [x, x', y, y', ...]: positions are the even coordinates of each axis pair
    C = np.zeros((n // 2, n))
    for i in range(n // 2):
        C[i, 2 * i] = 1.0
    return C


def saturation_certificate(A: Any, B: Any, K: Any, A_tau: Any, tau: float,
                           limits: SaturationLimits, *,
                           solver: str = 'CLARABEL', margin: float = 1e-7
                           ) -> SaturationCertificate:
    """Largest certified initial position error of the saturated loop (see module text).

    Parameters
    ----------
    A, B, K, A_tau : array_like
        The linearized robot (``n x n``, ``n x m``), the gain (``m x n``) and the delay
        matrix; positions are the even coordinates of ``xi`` (``[x, x', y, y']``).
    tau : float
        The state delay (s).
    limits : SaturationLimits
        Turn-rate and acceleration limits, the smallest speed and the reference
        acceleration.
    solver : str
        cvxpy solver.
    margin : float
        Strictness of the LMIs.

    Returns
    -------
    SaturationCertificate
        ``radius`` 0 and ``status`` explaining when nothing is certified.
    """
    import cvxpy as cp

    from .sdp import solve
    A, B, K, Ad = (np.asarray(M, float) for M in (A, B, K, A_tau))
    n, m = B.shape
    lev = limits.level
    if lev <= 0:
        z = np.zeros((n, n))
        return SaturationCertificate(limits, z, z, np.zeros((m, n)), np.eye(m), tau, 0.0, 0.0,
                                     math.inf, math.inf,
                                     f'reference acceleration {limits.max_reference_accel:g} '
                                     f'm/s^2 uses the whole input box ({limits.box:.4g} m/s^2)')
    Acl = A + B @ K
    C = _position_selector(n)
    # unit level: the LMIs are homogeneous in l (W scales with l^2)
    W = cp.Variable((n, n), symmetric=True)
    R = cp.Variable((n, n), symmetric=True)
    Z = cp.Variable((m, n))
    s = cp.Variable(m)
    beta = cp.Variable()
    S = cp.diag(s)
    M = cp.bmat([[Acl @ W + W @ Acl.T + R, Ad @ W, -B @ S + Z.T],
                 [W @ Ad.T, -R, np.zeros((n, m))],
                 [-S @ B.T + Z, np.zeros((m, n)), -2 * S]])
    cons = [0.5 * (M + M.T) << -margin * np.eye(2 * n + m), W >> margin * np.eye(n),
            R >> margin * np.eye(n), s >= margin]
    for i in range(m):
        row = cp.reshape(W @ K[i] - Z[i], (n, 1), order='C')
        Mi = cp.bmat([[W, row], [row.T, np.ones((1, 1))]])
        cons.append(0.5 * (Mi + Mi.T) >> 0)
    k = C.shape[0]
    Mb = cp.bmat([[beta * np.eye(k), C], [C.T, W]])
    cons.append(0.5 * (Mb + Mb.T) >> 0)
    prob = cp.Problem(cp.Minimize(beta), cons)
    out = solve(prob, solver, what='the saturation region LMI', quiet_inaccurate=True)
    if W.value is None:
        z = np.zeros((n, n))
        return SaturationCertificate(limits, z, z, np.zeros((m, n)), np.eye(m), tau, 0.0, 0.0,
                                     math.inf, math.inf, f'solver: {out.status}')
    Wv = 0.5 * (W.value + W.value.T) * lev ** 2
    Rs = np.asarray(R.value, float)
    Rv = 0.5 * (Rs + Rs.T) * lev ** 2
    Pv = np.linalg.inv(Wv)
    Pv = 0.5 * (Pv + Pv.T)
    Qv = Pv @ Rv @ Pv
    Qv = 0.5 * (Qv + Qv.T)
    Gv = (np.asarray(Z.value, float) * lev ** 2) @ Pv
    Tv = np.diag(1.0 / (np.asarray(s.value, float).ravel() * lev ** 2))
    # the solver's point lies on the inclusion boundary to its accuracy: shrink the
    # ellipsoid by that much (P, Q, T scaled together keep the first LMI's sign)
    H = K - Gv
    Winv = np.linalg.inv(Pv)
    incl = max(float(H[i] @ Winv @ H[i]) for i in range(m)) / lev ** 2
    c = max(incl, 1.0) * (1 + 1e-7)
    return verify_saturation(A, B, K, Ad, tau, limits, c * Pv, c * Qv, Gv, c * Tv,
                             status=out.status)


def verify_saturation(A: Any, B: Any, K: Any, A_tau: Any, tau: float, limits: SaturationLimits,
                      P: Any, Q: Any, G: Any, T: Any, *,
                      status: str = 'given') -> SaturationCertificate:
    """Check a saturation certificate in numpy and compute its radius.

    Parameters
    ----------
    A, B, K, A_tau : array_like
        The loop.
    tau : float
        The delay (s).
    limits : SaturationLimits
        The limits (the level ``l``).
    P, Q, G, T : array_like
        Lyapunov-Krasovskii matrices, the sector matrix ``G`` and the diagonal ``T``.
    status : str
        Where the point came from.

    Returns
    -------
    SaturationCertificate
        With ``max_eig`` of ``[[Acl'P + P Acl + Q, P A_tau, -P B + G'T], [*, -Q, 0],
        [*, *, -2T]]`` and the inclusion ratio; ``radius`` 0 unless both pass.
    """
    A, B, K, Ad, P, Q, G, T = (np.asarray(M, float) for M in (A, B, K, A_tau, P, Q, G, T))
    n, m = B.shape
    Acl = A + B @ K
    L = np.block([[Acl.T @ P + P @ Acl + Q, P @ Ad, -P @ B + G.T @ T],
                  [Ad.T @ P, -Q, np.zeros((n, m))],
                  [(-P @ B + G.T @ T).T, np.zeros((m, n)), -2 * T]])
    # the certificate check of the LMI modules (no relative slack here: tol = 0)
    max_eig, scale, min_p = eigen_figures(sym(L), (P,))
    lev = limits.level
    Pinv = np.linalg.inv(P)
    H = K - G
    incl = float(max(H[i] @ Pinv @ H[i] for i in range(m)) / lev ** 2) if lev > 0 else math.inf
    C = _position_selector(n)
    Pt = P + tau * Q
    # e0 = C' z (zero velocity error): e0' Pt e0 <= 1 for all ||z|| <= r
    lam = float(np.linalg.eigvalsh(C @ Pt @ C.T).max())
    ok = passes(max_eig, scale, min_p, None, 0.0) and incl <= 1 + 1e-9
    radius = 1.0 / math.sqrt(lam) if ok and lam > 0 else 0.0
    per = radius / lev if lev > 0 else 0.0
    return SaturationCertificate(limits, P, Q, G, T, float(tau), radius, per, max_eig, incl,
                                 status)


def simulate_saturated(A: Any, B: Any, K: Any, A_tau: Any, tau: float,
                       limits: SaturationLimits, e0: Any, *, duration: float = 20.0,
                       dt: float = 5e-3, u_d: Callable[[float], Any] | None = None
                       ) -> np.ndarray:
    """The saturated error loop from a constant history ``e0`` (RK-free Euler, small ``dt``).

    Parameters
    ----------
    A, B, K, A_tau : array_like
        The loop.
    tau : float
        The state delay (s).
    limits : SaturationLimits
        The input box.
    e0 : array_like, shape (n,)
        The constant initial history.
    duration : float, optional
        Simulated time (s).
    dt : float, optional
        Euler step (s).
    u_d : callable, optional
        ``t -> (m,)`` reference acceleration (default 0).

    Returns
    -------
    numpy.ndarray, shape (steps + 1, n)
        The error trajectory, a row per step.
    """
    A, B, K, Ad = (np.asarray(M, float) for M in (A, B, K, A_tau))
    n, m = B.shape
    steps = int(round(duration / dt))
    d = max(int(round(tau / dt)), 0)
    e = np.asarray(e0, float).copy()
    hist = [e.copy()] * (d + 1)
    box = limits.box
    out = np.empty((steps + 1, n))
    out[0] = e
    for k in range(steps):
        ud = np.zeros(m) if u_d is None else np.asarray(u_d(k * dt), float)
        u = np.clip(ud + K @ e, -box, box) - ud
        e_del = hist[-(d + 1)] if d else e
        e = e + dt * (A @ e + B @ u + Ad @ e_del)
        hist.append(e.copy())
        if len(hist) > d + 1:
            hist.pop(0)
        out[k + 1] = e
    return out


def format_saturation(cert: SaturationCertificate) -> str:
    """A few lines: the limits, the certified radius, the largest reference acceleration.

    Parameters
    ----------
    cert : SaturationCertificate
        The certificate.

    Returns
    -------
    str
    """
    lim = cert.limits
    head = (f'saturation (|w| <= {lim.max_angular_speed:g} rad/s at |v| >= {lim.min_speed:g} '
            f'm/s' + (f', |dv/dt| <= {lim.max_linear_accel:g} m/s^2' if lim.max_linear_accel
                      else '') + f': |u_i| <= {lim.box:.4g} m/s^2; reference acceleration '
            f'<= {lim.max_reference_accel:g} m/s^2)')
    if not cert.verified:
        return f'{head}\n  nothing certified: {cert.status}'
    return (f'{head}\n  certified region of attraction (generalized sector condition): every '
            f'initial position error up to {cert.radius * 1e3:.4g} mm (zero velocity error, '
            f'constant history) converges\n  with zero reference acceleration: up to '
            f'{cert.radius_per_level * lim.box * 1e3:.4g} mm; the largest reference '
            f'acceleration with {cert.radius * 500:.3g} mm certified: '
            f'{cert.max_reference_accel(cert.radius / 2):.4g} m/s^2\n  numpy check: max eig '
            f'{cert.max_eig:.3g} < 0, inclusion {cert.inclusion:.6f} <= 1')


@dataclass(frozen=True)
class SimulationCheck:
    """Simulated starts on circles of position error: inside and just outside the radius."""

    inside_radius: float
    inside_converged: int
    inside_total: int
    outside_radius: float
    outside_converged: int
    outside_total: int


def check_by_simulation(cert: SaturationCertificate, A: Any, B: Any, K: Any, A_tau: Any, *,
                        directions: int = 8,
                        inside: float = 0.99, outside: float = 1.5, duration: float = 20.0,
                        tolerance: float = 1e-3) -> SimulationCheck:
    """Simulate the saturated loop from position errors at ``inside`` and ``outside`` x radius.

    Parameters
    ----------
    cert : SaturationCertificate
        A verified certificate.
    A, B, K, A_tau : array_like
        The loop.
    directions : int
        Starts per circle (equally spaced angles).
    inside, outside : float
        Radii of the two circles as fractions of ``cert.radius``.
    duration : float
        Simulated time (s).
    tolerance : float
        Converged: the final error norm below ``tolerance`` x the initial one.

    Returns
    -------
    SimulationCheck
        How many starts converged on each circle (reference acceleration: a vector of
        magnitude ``max_reference_accel`` per component turning at 1 rad/s).
    """
    n = np.asarray(A).shape[0]
    d = cert.limits.max_reference_accel

    def u_d(t: float) -> np.ndarray:
        return d * np.array([math.cos(t), math.sin(t)])

    counts = []
    for frac in (inside, outside):
        ok = 0
        for j in range(directions):
            ang = 2 * math.pi * j / directions
            e0 = np.zeros(n)
            e0[0], e0[2] = (frac * cert.radius * math.cos(ang),
                            frac * cert.radius * math.sin(ang))
            traj = simulate_saturated(A, B, K, A_tau, cert.tau, cert.limits, e0,
                                      duration=duration, u_d=u_d)
            ok += int(np.linalg.norm(traj[-1]) < tolerance * np.linalg.norm(e0))
        counts.append(ok)
    return SimulationCheck(inside * cert.radius, counts[0], directions,
                           outside * cert.radius, counts[1], directions)
