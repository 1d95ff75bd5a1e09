r"""The input-delay certificate: its records and its independent check in numpy.

The records of :mod:`.input_delay` (:class:`InputDelayVerification`,
:class:`InputDelayCertificate`, :class:`InputDelayResult`), the block rows of ``Phi_0``
shared by the check and the SDP (:func:`phi_rows`), and :func:`verify_input_delay`, which
uses nothing from the solver but the returned matrices.  The condition and its
derivation are in doc/theory.md, section "Input delay (command latency)"
(#input-delay-command-latency).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ...errors import InputError
from .certificate import CertifiedGain, Verification, eigen_figures, passes, signs_hold
from .problem import Problem
from .sdp import sym

__all__ = ['InputDelayVerification', 'InputDelayCertificate', 'InputDelayResult', 'Weights',
           'weights', 'phi_rows', 'input_delay_verification_matrix', 'verify_input_delay',
           'check_interval']


# ---------------------------------------------------------------------------------------------
# records

@dataclass(frozen=True)
class InputDelayVerification(Verification):
    """Outcome of :func:`verify_input_delay` (:class:`.certificate.Verification`).

    Eigenvalues in original coordinates.

    Besides ``ok`` and the keywords ``tolerance`` and ``scale`` of the base:

    Parameters
    ----------
    max_eig_Psi : float
        Largest eigenvalue of ``Psi`` (must be ``< -tolerance * scale``).
    min_eig_lyapunov : float
        Smallest eigenvalue over ``P, S0, S1, R0, R1`` (and ``Q``): must be > 0.
    min_eig_rc : float
        Smallest eigenvalue of ``[[R1, S12], [S12^T, R1]]``: must be > 0.
    lam : float or None
        Petersen scalar (> 0; ``None``: nominal).
    congruent : bool
        Acceptance decided in the congruent coordinates ``T^T Psi T``,
        ``T = diag(P2^-1, I)`` (see :func:`verify_input_delay`); ``max_eig_Psi`` and
        ``scale`` are still of ``Psi``.
    """

    max_eig_Psi: float
    min_eig_lyapunov: float
    min_eig_rc: float
    lam: float | None
    congruent: bool = False

    MATRIX = 'Psi'
    WORST = 'max_eig_Psi'
    POSITIVE = (('min_eig_lyapunov', 'of the Lyapunov matrices'),
                ('min_eig_rc', 'of the reciprocally convex block'))


@dataclass(frozen=True)
class InputDelayCertificate:
    """Lyapunov-Krasovskii certificate (original coordinates), doc/theory.md step 4/5.

    ``Q is None``: no state-delay term; ``lam is None``: nominal (``D = 0``).
    """

    P: np.ndarray
    P2: np.ndarray
    P3: np.ndarray
    S0: np.ndarray
    S1: np.ndarray
    R0: np.ndarray
    R1: np.ndarray
    S12: np.ndarray
    Q: np.ndarray | None
    lam: float | None


@dataclass(frozen=True, kw_only=True)
class InputDelayResult(CertifiedGain):
    """A gain certified for input delays in ``[h_min, h_max]`` with decay rate ``alpha``.

    The fields of :class:`.certificate.CertifiedGain` (keywords) and:

    Parameters
    ----------
    h_min, h_max : float
        The certified latency interval (s).
    alpha : float
        The certified decay rate (1/s).
    eps : float
        The tuning scalar (``P3 = eps P2``).
    verification : InputDelayVerification
        The numpy check of ``certificate`` (always ``ok``).
    state_delay : bool
        ``A_tau`` is in the certificate.
    gain_bound : float or None
        The ``||K||_2`` bound imposed.
    eps_scan : tuple of (float, float)
        ``(eps, t)`` of every solve.
    """

    h_min: float
    h_max: float
    alpha: float
    eps: float
    certificate: InputDelayCertificate
    verification: InputDelayVerification
    state_delay: bool
    gain_bound: float | None
    eps_scan: tuple[tuple[float, float], ...] = ()


# ---------------------------------------------------------------------------------------------
# independent verification (numpy only)

class Weights(NamedTuple):
    """The scalars of ``Phi_0``: numbers, or cvxpy parameters in a cached program."""

    two_a: Any          # 2 alpha
    w0: Any             # exp(-2 alpha h_min)
    w1: Any             # exp(-2 alpha h_max)
    wt: Any             # exp(-2 alpha tau)
    h0sq: Any           # h_min^2
    h10sq: Any          # (h_max - h_min)^2


def weights(h_min: float, h_max: float, alpha: float, tau: float) -> Weights:
    """The scalars of ``Phi_0`` for a latency interval, decay rate and state delay.

    Parameters
    ----------
    h_min, h_max : float
        The latency interval (s).
    alpha : float
        The decay rate (1/s).
    tau : float
        The state delay (s).

    Returns
    -------
    Weights
    """
    h0, h1, a = float(h_min), float(h_max), float(alpha)
    h10 = h1 - h0
    return Weights(2 * a, math.exp(-2 * a * h0), math.exp(-2 * a * h1),
                    math.exp(-2 * a * float(tau)), h0 * h0, h10 * h10)


def phi_rows(A: Any, A1: Any, A_tau: Any, wt: Weights, P: Any, P2: Any, P3: Any, S0: Any,
              S1: Any, R0: Any, R1: Any, S12: Any, Q: Any
              ) -> list[list[Any]]:
    """Block rows of ``Phi_0`` (doc/theory.md, input delay, step 4).

    Numpy arrays or cvxpy expressions (``A``, ``A1 = B K``, ``A_tau`` and the weights may be
    cvxpy parameters).

    Parameters
    ----------
    A, A1, A_tau : array or cvxpy expression
        The plant, ``B K`` and the state-delay matrix.
    wt : Weights
        The scalars (:func:`weights`).
    P, P2, P3, S0, S1, R0, R1, S12 : array or cvxpy expression
        The functional's matrices.
    Q : array, cvxpy expression or None
        The state-delay term (``None``: none).

    Returns
    -------
    list of list
        The block rows.
    """
    n = A.shape[0]
    w0, w1 = wt.w0, wt.w1
    Z = np.zeros((n, n))
    b11 = P2.T @ A + A.T @ P2 + wt.two_a * P + S0 - w0 * R0
    b12 = P - P2.T + A.T @ P3
    b22 = -(P3 + P3.T) + wt.h0sq * R0 + wt.h10sq * R1
    rows = [
        [b11, b12, w0 * R0, P2.T @ A1, Z],
        [b12.T, b22, Z, P3.T @ A1, Z],
        [w0 * R0, Z, w0 * (S1 - S0 - R0) - w1 * R1, w1 * (R1 - S12), w1 * S12],
        [(P2.T @ A1).T, (P3.T @ A1).T, w1 * (R1 - S12).T, w1 * (S12 + S12.T - 2 * R1),
         w1 * (R1 - S12)],
        [Z, Z, w1 * S12.T, w1 * (R1 - S12).T, -w1 * (S1 + R1)],
    ]
    if Q is not None:
        rows[0][0] = rows[0][0] + Q
        cols = [P2.T @ A_tau, P3.T @ A_tau, Z, Z, Z]
        for r, c in zip(rows, cols):
            r.append(c)
        rows.append([c.T for c in cols] + [-wt.wt * Q])
    return rows


def input_delay_verification_matrix(A: np.ndarray, B: np.ndarray, A_tau: np.ndarray,
                                    tau: float, E: np.ndarray, F: np.ndarray, K: np.ndarray,
                                    h_min: float, h_max: float, alpha: float,
                                    cert: InputDelayCertificate) -> np.ndarray:
    """``Psi`` of the input-delay condition (doc/theory.md, step 4/5), symmetric.

    ``Phi_0`` alone when ``cert.lam is None``; ``A_tau`` is ignored (no state-delay
    block) when ``cert.Q is None``.

    Parameters
    ----------
    A, B, A_tau, E, F, K : numpy.ndarray
        Plant, perturbation structure and gain, as in :func:`.lmi.verification_matrix`.
    tau : float
        The state delay (s).
    h_min, h_max : float
        The latency interval (s).
    alpha : float
        The decay rate (1/s).
    cert : InputDelayCertificate
        The certificate's matrices.

    Returns
    -------
    numpy.ndarray
    """
    n = A.shape[0]
    c = cert
    rows = phi_rows(A, B @ K, A_tau, weights(h_min, h_max, alpha, tau), c.P, c.P2, c.P3,
                     c.S0, c.S1, c.R0, c.R1, c.S12, c.Q)
    phi = sym(np.block(rows))
    if cert.lam is None:
        return phi
    lam = float(cert.lam)
    k = len(rows)
    q, p = E.shape[1], F.shape[0]
    BE = B @ E
    U = np.vstack([c.P2.T @ BE, c.P3.T @ BE] + [np.zeros((n, q))] * (k - 2))
    V = np.hstack([np.zeros((p, 3 * n)), F] + [np.zeros((p, n))] * (k - 4))
    psi = np.block([[phi, lam * U, V.T],
                    [lam * U.T, -lam * np.eye(q), np.zeros((q, p))],
                    [V, np.zeros((p, q)), -lam * np.eye(p)]])
    return sym(psi)


def _congruent_ok(Psi: np.ndarray, P2: np.ndarray, n: int, k: int, tol: float) -> bool:
    """``T^T Psi T < -tol ||T^T Psi T|| I`` beyond its rounding error, ``T = diag(P2^-1, .., I)``.

    Sylvester's law of inertia: for an invertible ``T``, ``Psi < 0`` iff ``T^T Psi T < 0``,
    so both are the same certificate; the relative acceptance test differs.  ``Psi`` is in
    the original coordinates, where a point that is strict in the solver's coordinates
    (``X = P2^-1``, doc/theory.md step 6) has ``max eig`` of about ``-t / ||X||^2``
    next to a norm of about ``||Psi_bar|| cond(X)^2``: with ``cond(X)`` of 50 a point with
    ``t = 0.05`` fails ``tol = 1e-9`` there by rounding-free arithmetic alone.  The test
    is repeated where the solver imposed its margin, with the same ``tol``, and accepted
    only if the margin also exceeds a bound of the floating-point error of forming
    ``T^T Psi T`` and of its eigenvalues (``8 N u ||T||^2 ||Psi||``, ``N`` the size,
    ``u`` the unit round-off): the returned matrices, not the solver, are what is checked.
    """
    try:
        Xi = np.linalg.inv(np.asarray(P2, float))
    except np.linalg.LinAlgError:
        return False
    N = Psi.shape[0]
    T = np.eye(N)
    for i in range(min(k, N // n)):
        T[i * n:(i + 1) * n, i * n:(i + 1) * n] = Xi
    if not np.all(np.isfinite(T)):
        return False
    Pb = sym(T.T @ Psi @ T)
    ev = np.linalg.eigvalsh(Pb)
    top, scale = float(ev[-1]), float(np.max(np.abs(ev)))
    rounding = 8.0 * N * np.finfo(float).eps * float(np.linalg.norm(T, 2)) ** 2 \
        * float(np.linalg.norm(Psi, 2))
    return bool(top < -max(tol * scale, rounding))


def verify_input_delay(problem: Problem, K: Any, h_min: float, h_max: float,
                       certificate: InputDelayCertificate, *, alpha: float = 0.0,
                       tol: float = 1e-9) -> InputDelayVerification:
    """Check the input-delay condition from ``K``, the interval, ``alpha`` and the matrices.

    Passes iff ``P, S0, S1, R0, R1 (, Q) > 0``, ``[[R1, S12], [S12^T, R1]] > 0``,
    ``lam > 0`` (unless nominal) and ``max eig(Psi) < -tol * ||Psi||``.  Uses nothing
    from the solver but the matrices in ``certificate``.  Never raises for a failed
    check: see ``ok``.

    When only the relative slack fails, the test is repeated in the solver's congruent
    coordinates (``_congruent_ok``; ``congruent`` of the result).

    Parameters
    ----------
    problem, K, tol
        As in :func:`.lmi.verify_certificate` (``tol``: the slack demanded of ``Psi``).
    h_min, h_max : float
        The latency interval (s).
    certificate : InputDelayCertificate
        The matrices.
    alpha : float, optional
        The decay rate the certificate shows (1/s).

    Returns
    -------
    InputDelayVerification
    """
    K = problem.gain(K)
    check_interval(h_min, h_max)
    c = certificate
    Psi = input_delay_verification_matrix(problem.A, problem.B, problem.A_tau, problem.tau,
                                          problem.E, problem.F, K, h_min, h_max, alpha, c)
    lyap = [c.P, c.S0, c.S1, c.R0, c.R1] + ([] if c.Q is None else [c.Q])
    rc = np.block([[c.R1, c.S12], [c.S12.T, c.R1]])
    top, scale, mins = eigen_figures(Psi, lyap + [rc])
    min_l, min_rc = min(mins[:-1]), mins[-1]
    ok = passes(top, scale, mins, c.lam, tol)
    congruent = False
    if not ok and top < 0 and signs_hold(mins, c.lam):
        # the sign conditions hold, the relative slack not: try the solver's coordinates
        congruent = _congruent_ok(Psi, c.P2, problem.n, 5 if c.Q is None else 6, tol)
        ok = congruent
    return InputDelayVerification(bool(ok), top, min_l, min_rc, c.lam, congruent,
                                  tolerance=tol, scale=scale)


# ---------------------------------------------------------------------------------------------
# argument checks

def check_interval(h_min: Any, h_max: Any) -> tuple[float, float]:
    """The latency interval as floats, or :class:`.InputError` for a bad one.

    Parameters
    ----------
    h_min, h_max : float
        The interval (s): finite, ``0 <= h_min <= h_max``, ``h_max > 0``.

    Returns
    -------
    (float, float)
    """
    try:
        h0, h1 = float(h_min), float(h_max)
    except (TypeError, ValueError):
        raise InputError(f'delay interval must be two numbers (seconds), got '
                         f'[{h_min!r}, {h_max!r}]') from None
    if not (math.isfinite(h0) and math.isfinite(h1) and 0 <= h0 <= h1 and h1 > 0):
        raise InputError(f'delay interval must satisfy 0 <= h_min <= h_max, h_max > 0 '
                         f'(seconds, finite), got [{h_min!r}, {h_max!r}]')
    return h0, h1
