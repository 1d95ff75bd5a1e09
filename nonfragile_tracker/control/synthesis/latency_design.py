"""From "my robot has this latency" to a certified tracker gain with its figures.

:func:`design_for_latency` runs the input-delay synthesis of :mod:`.input_delay` for a
latency interval ``[h_min, h_max]`` (and an optional first-order actuator lag, certified on
the exact lagged loop, :func:`lagged_problem`), measures the returned gain with the exact
delay-loop analysis of :mod:`.delay` (:func:`exact_abscissa`, over the perturbations of
:func:`perturbation_set`) and returns everything a gain file records
(:meth:`LatencyDesign.metadata`); its figures are settled on a 3-digit grid
(:data:`FIGURE_DIGITS`) so that every machine records the same.

See doc/theory.md, section "Synthesis choices" (the ``latency-design`` entry: the lag, the
exact figures, the cost and the same figures on every CPU).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from ...errors import InputError
from .errors import CertificateError, InfeasibleError, SolverFailure
from .delay import chebyshev_differentiation, delay_margin
from .input_delay import (InputDelayResult, certified_input_delay_of_gain, certify_input_delay,
                          max_certified_input_delay, max_input_delay_decay_rate,
                          synthesize_input_delay)
from ..identification.identify import Identification
from ..validate import as_finite_float
from .problem import Problem
from .search import largest_feasible_bracketed, resolution, settle_on_grid

__all__ = ['OBJECTIVES', 'LatencyDesign', 'LatencyPlan', 'lagged_problem', 'perturbation_set',
           'exact_abscissa', 'exact_figures', 'design_for_latency', 'latency_figures',
           'delay_interval', 'plan_from_identification', 'GAIN_COMPENSATED',
           'certify_turn_gain_uncertainty', 'gain_verdict']

OBJECTIVES = ('decay', 'max-delay')
#: A static channel gain is compensated when its interval excludes 1 and it is more than this
#: far from 1 (a skid-steer's turn gain, 0.6-0.7; a few per mille of creep is not).
GAIN_COMPENSATED = 0.02
#: First trial of the certified-latency search, as a fraction of the exact margin: the
#: certified latency of the paper's designs is 0.80-0.86 of it (with and without a lag),
#: so the search starts with a short bracket (any value is correct, only the count changes).
GUESS_OF_MARGIN = 0.8


@dataclass(frozen=True)
class LatencyDesign:
    """A certified latency design and the figures that describe it."""

    problem: str
    objective: str
    K: np.ndarray
    gain_bound: float | None
    h_min: float
    h_max: float                  # the latency interval asked for
    lag: float                    # actuator time constant (s), 0: none
    certified_h_max: float        # largest h_max certified for this K (alpha = 0, no lag)
    decay_rate: float             # certified decay rate on [h_min, h_max] (1/s)
    lag_certified_h_max: float | None   # largest h_max certified with the lag (None: no lag)
    true_delay_margin: float      # exact, min over the perturbation set (lagged loop if lag)
    abscissa_at_h_max: float      # exact worst spectral abscissa at h = h_max (same loop)
    state_delay: bool             # A_tau included in the certificate
    synthesis: InputDelayResult
    worst_abscissa: float = math.nan     # exact worst abscissa over [h_min, h_max] (same loop)

    @property
    def gain_norm(self) -> float:
        """Spectral norm ``||K||_2`` of the gain."""
        return float(np.linalg.norm(self.K, 2))

    def metadata(self) -> dict[str, Any]:
        """Flat, ROS-parameter-compatible description (numbers, strings, bools, lists)."""
        out: dict[str, Any] = {
            'method': 'input-delay LMI (descriptor, Jensen + reciprocally convex)',
            'problem': self.problem, 'objective': self.objective,
            'latency_interval': [self.h_min, self.h_max], 'actuator_lag': self.lag,
            'gain_norm': self.gain_norm,
            'certified_h_max': self.certified_h_max,
            'certified_decay_rate': self.decay_rate,
            'true_delay_margin': self.true_delay_margin,
            'abscissa_at_h_max': self.abscissa_at_h_max,
            'state_delay_in_certificate': self.state_delay,
            'state_delay_in_exact_check': True,
            'exact_figures_loop': 'lagged' if self.lag else 'no lag',
            'worst_abscissa_on_interval': self.worst_abscissa,
            'verification_max_eig': self.synthesis.verification.max_eig_Psi,
        }
        if self.gain_bound is not None:
            out['gain_bound'] = float(self.gain_bound)
        if self.lag_certified_h_max is not None:
            out['lag_certified_h_max'] = self.lag_certified_h_max
        return {k: (float(v) if isinstance(v, (float, np.floating)) else v)
                for k, v in out.items()}

    def summary(self) -> str:
        """Human-readable lines (also written as the gain file's comment).

        Only figures of the loop the design is for: with an actuator lag, the lagged
        loop's certified latency and exact figures (not those of the loop without it).
        Each figure is printed to the precision that holds on every machine: the decay
        rate and latency certified to :data:`FIGURE_DIGITS` digits (grid values, the same
        under every BLAS kernel), the exact delay margin to 4, the worst abscissa to 2
        (a property of ``K``, which moves by about 1 % with the solver's last digits: the
        decay rate is a flat function of it; doc/across-machines.md).
        """
        lines = [
            f'input-delay design ({self.objective}) for problem {self.problem!r}: latency '
            f'h(t) in [{self.h_min:g}, {self.h_max:g}] s'
            + (f', actuator lag {self.lag:g} s' if self.lag else ''),
            f'K =\n{np.array2string(self.K, precision=6, suppress_small=True)}',
            f'||K||_2 = {self.gain_norm:.6g}'
            + (f' (bound {self.gain_bound:g})' if self.gain_bound is not None else ''),
        ]
        if self.lag_certified_h_max is not None:
            lines.append(f'certified (with the actuator lag {self.lag:g} s): every latency in '
                         f'[{self.h_min:g}, {self.lag_certified_h_max:.4g}] s (time-varying), '
                         f'||Delta|| <= 1')
        else:
            lines.append(f'certified: every latency in [{self.h_min:g}, '
                         f'{self.certified_h_max:.4g}] s (time-varying), ||Delta|| <= 1')
        if self.objective == 'decay':
            lines.append(f'certified decay rate {self.decay_rate:.4g} 1/s on [{self.h_min:g}, '
                         f'{self.h_max + self.lag:g}] s'
                         + (' (without the lag, latency widened by it: the synthesis)'
                            if self.lag else ''))
        loop = 'lagged loop, ' if self.lag else ''
        worst = self.worst_abscissa if math.isfinite(self.worst_abscissa) \
            else self.abscissa_at_h_max
        lines.append(f'exact ({loop}constant delay and Delta, state delay included): delay '
                     f'margin {self.true_delay_margin:.4g} s, worst spectral abscissa on '
                     f'[{self.h_min:g}, {self.h_max:g}] s {worst:.2g}')
        lines.append(f'verification: max eig Psi = '
                     f'{self.synthesis.verification.max_eig_Psi:.4g} -> OK')
        return '\n'.join(lines)


def certify_turn_gain_uncertainty(problem: Problem, K: Any, h_min: float, h_max: float,
                                  eps: float, lag: float = 0.0) -> bool:
    """Whether ``K`` stays certified when the base's turn rate is off by up to ``eps``.

    A turn-rate gain ``1 + delta`` (``|delta| <= eps``: what is left of a compensated
    ``gain_w``'s interval) scales the normal component of the law's input: ``u`` becomes
    ``(I + delta n n^T) u`` with ``n`` the unit normal of the heading, a time-varying
    multiplicative input uncertainty ``B (I + Delta(t)) K``, ``||Delta|| <= eps``.  It is
    added to the problem's own ``E D F`` as a second block, ``E' = [E, s I]``,
    ``F' = [F; s K]`` with ``s = sqrt(eps)``: one full ``||D|| <= 1`` contains
    ``diag(D_1, D_2)``, so the certificate covers ``E D_1 F + eps D_2 K`` (and the cross
    terms, ``s``-scaled: conservative; without the scaling they are the whole ``E D K``), and
    the input-delay condition is decided for ``[h_min, h_max]`` through the lag.  Covers the
    feedback loop; the feedforward's share of the error (``delta`` times the reference's
    normal acceleration) is a bounded disturbance, not covered.

    Parameters
    ----------
    problem : Problem
        The loop (its ``E``, ``F`` are kept).
    K : array_like, shape (m, n)
        The gain.
    h_min, h_max : float
        The residual delay interval (s) certified.
    eps : float
        The relative turn-gain uncertainty (>= 0).
    lag : float, optional
        Actuator time constant (s); 0 for none.

    Returns
    -------
    bool
    """
    K = np.asarray(K, dtype=float)
    eps = as_finite_float(eps, 'eps', low=0.0)
    m = problem.m
    s = math.sqrt(eps)
    p = Problem(A=problem.A, B=problem.B, A_tau=problem.A_tau, tau=problem.tau,
                E=np.hstack([problem.E, s * np.eye(m)]), F=np.vstack([problem.F, s * K]),
                name=f'{problem.name}+gain{eps:g}', options=dict(problem.options))
    if lag > 0:
        p = lagged_problem(p, lag)
        K = np.hstack([K, np.zeros((m, m))])
    return bool(certify_input_delay(p, K, h_min, h_max).certified)


def gain_verdict(plan: LatencyPlan, problem: Problem, K: Any
                 ) -> tuple[str, dict[str, Any]] | None:
    """What the certificate says of the compensated gains' remaining uncertainty, if any.

    A compensated turn gain: :func:`certify_turn_gain_uncertainty` with the relative width
    left of its interval.  A compensated speed gain acts on the speed state, not on the
    input: not covered, and said so.

    Parameters
    ----------
    plan : LatencyPlan
        The plan (its compensated gains and their intervals, delay interval and lag).
    problem : Problem
        The loop the gain was designed for.
    K : array_like
        The designed gain.

    Returns
    -------
    (str, dict) or None
        A line for the summary and the design record's entries; ``None`` when no gain is
        compensated.
    """
    gains = plan.gain_parameters()
    if not gains:
        return None
    if 'gain_v' in gains:
        return ('the certificate does not cover the compensated speed gain\'s uncertainty (it '
                'acts on the speed state, which the LMIs do not model)',
                {'gain_uncertainty_certified': False})
    g = gains['gain_w']
    lo, hi = plan.gain_intervals[1]
    eps = max(hi / g - 1.0, 1.0 - lo / g, 0.0)
    ok = certify_turn_gain_uncertainty(problem, K, plan.h_min, plan.h_max, eps, plan.lag)
    return (f'turn gain {g:.4f} compensated; with its remaining uncertainty +-{100 * eps:.2f} % '
            f'(a multiplicative input uncertainty) the gain is '
            f'{"certified" if ok else "NOT certified"} for the residual delay '
            f'[{plan.h_min:.4f}, {plan.h_max:.4f}] s through the lag {plan.lag:.4f} s '
            '(the feedback loop; the feedforward\'s share is a bounded error, not covered)',
            {'turn_gain_uncertainty': eps, 'gain_uncertainty_certified': ok})


def lagged_problem(problem: Problem, lag: float) -> Problem:
    """The loop with a first-order actuator lag: state ``(xi, u_act)``, gain ``[K, 0]``.

    ``A = [[A, B], [0, -I/T]]``, ``B = [0; I/T]``, ``A_tau = diag(A_tau, 0)``,
    ``E`` unchanged, ``F = [F, 0]``.

    Parameters
    ----------
    problem : Problem
        The loop without the lag.
    lag : float
        The actuator time constant ``T`` (s, > 0).

    Returns
    -------
    Problem
        The augmented problem (``n + m`` states).
    """
    T = float(lag)
    if not (math.isfinite(T) and T > 0):
        raise InputError(f'actuator lag must be a finite time constant > 0 (s), got {lag!r}')
    n, m = problem.n, problem.m
    A = np.block([[problem.A, problem.B], [np.zeros((m, n)), -np.eye(m) / T]])
    B = np.vstack([np.zeros((n, m)), np.eye(m) / T])
    Ad = np.zeros((n + m, n + m))
    Ad[:n, :n] = problem.A_tau
    F = np.hstack([problem.F, np.zeros((problem.F.shape[0], m))])
    return Problem(A=A, B=B, A_tau=Ad, tau=problem.tau, E=problem.E, F=F,
                   name=f'{problem.name}+lag{T:g}', perturbations=dict(problem.perturbations),
                   options=dict(problem.options))


def perturbation_set(problem: Problem, K: np.ndarray | None = None,
                     h: float | None = None) -> list[np.ndarray]:
    """``D = 0``, the listed perturbations, ``+-I`` and, given ``K``, the worst ``D`` searched.

    With ``K``, the worst ``||D||_2 <= 1`` found by :func:`.worst_delta.worst_delta` (the
    extreme points of the ball for ``D``'s shape, then a local search) is added: the one
    with the smallest one-delay margin (``A_tau`` left out) and, given ``h``, the one with
    the largest abscissa of the two-delay loop at ``h``.

    Parameters
    ----------
    problem : Problem
        Its ``E``, ``F`` and ``perturbations``.
    K : numpy.ndarray, optional
        The gain the figures are of (the searched worst cases depend on it).
    h : float, optional
        The input delay (s) at which the worst abscissa is searched.

    Returns
    -------
    list of numpy.ndarray
        The constant perturbations the exact figures are taken over.
    """
    q, p = problem.E.shape[1], problem.F.shape[0]
    out = [np.zeros((q, p))] + [np.asarray(D, float) for D in problem.perturbations.values()]
    if q == p:
        out += [np.eye(q), -np.eye(q)]
    if K is not None:
        from .worst_delta import worst_delta
        B, E, F = problem.B, problem.E, problem.F
        out.append(worst_delta(lambda D: -min(delay_margin(problem.A, B @ (K + E @ D @ F)), 1e3),
                               q, p, extra=out)[1])
        if h is not None:
            out.append(worst_delta(lambda D: exact_abscissa(
                problem.A, problem.A_tau, problem.tau, B @ (K + E @ D @ F), float(h)),
                q, p, extra=out)[1])
    return out


def _interpolation_row(x: np.ndarray, t: float) -> np.ndarray:
    """Barycentric Lagrange weights at ``t`` for the Chebyshev extremal nodes ``x``."""
    N = len(x) - 1
    w = (-1.0) ** np.arange(N + 1)
    w[0] *= 0.5
    w[-1] *= 0.5
    d = t - x
    hit = np.flatnonzero(np.abs(d) < 1e-14)
    if hit.size:
        out = np.zeros(N + 1)
        out[hit[0]] = 1.0
        return out
    c = w / d
    return cast(np.ndarray, c / c.sum())


def exact_abscissa(A: np.ndarray, A_tau: np.ndarray, tau: float, A1: np.ndarray, h: float,
                   *, N: int | None = None) -> float:
    """Spectral abscissa of ``x' = A x + A_tau x(t - tau) + A1 x(t - h)`` (constant delays).

    Chebyshev collocation of the infinitesimal generator on ``[-r, 0]``,
    ``r = max(tau, h)`` (Breda, Maset, Vermiglio), the delayed states read by barycentric
    interpolation; the rightmost roots converge spectrally in ``N``: on the paper's loops
    (with and without a 50 ms lag, delays up to 0.3 s) ``N = 10`` already agrees with
    ``N = 60`` to 2e-11 and with :func:`.delay.spectral_abscissa` (one delay) to 1e-9
    (see the tests).  The default keeps the generator below about 90 rows (its dense
    eigenvalues are then a millisecond, where a multithreaded BLAS on a loaded machine
    takes up to a second for larger ones).

    Parameters
    ----------
    A, A_tau, A1 : ndarray, shape (n, n)
        Undelayed, state-delay and input-delay matrices.
    tau, h : float
        The two delays (s), ``>= 0``.
    N : int, optional
        Degree of the collocation (default ``max(10, 90 // n - 1)``).
    """
    n = A.shape[0]
    N = max(10, 90 // max(n, 1) - 1) if N is None else int(N)
    terms = [(M, float(d)) for M, d in ((A1, h), (A_tau, tau)) if np.any(M)]
    A0 = A + sum((M for M, d in terms if d <= 0), np.zeros((n, n)))
    terms = [(M, d) for M, d in terms if d > 0]
    if not terms:
        return float(np.max(np.linalg.eigvals(A0).real))
    r = max(d for _, d in terms)
    x = np.cos(np.pi * np.arange(N + 1) / N)
    G = np.kron(chebyshev_differentiation(N) * (2.0 / r), np.eye(n))
    G[:n, :] = 0.0
    G[:n, :n] = A0
    for M, d in terms:
        G[:n, :] += np.kron(_interpolation_row(x, 1.0 - 2.0 * d / r), M)
    return float(np.max(np.linalg.eigvals(G).real))


def _margin(problem: Problem, A1: np.ndarray, h_lo: float, guess: float) -> float:
    """Smallest ``h >= h_lo`` at which the two-delay loop has a root on the axis (1e-4 s).

    From the one-delay margin ``guess``: steps up or down to a bracket, then false
    position on the abscissa (smooth in ``h``), :func:`.search.largest_feasible_bracketed`.
    """
    def trial(h: float) -> tuple[float, bool | None]:
        a = exact_abscissa(problem.A, problem.A_tau, problem.tau, A1, h)
        return -a, (True if a < 0 else None)

    s_lo, ok = trial(h_lo)
    if ok is None:
        return float(h_lo)
    limit = max(4.0 * h_lo, 2.0)
    g = min(max(guess, h_lo), limit) if math.isfinite(guess) else limit
    lo, hi, s_hi = h_lo, math.nan, math.nan
    step = max(0.02 * g, 1e-3)
    h = g
    while True:
        sc, ok = trial(h)
        if ok is None:
            hi, s_hi = h, sc
            break
        lo, s_lo = h, sc
        if h >= limit:
            return math.inf
        h, step = min(h + step, limit), 2 * step
    if hi == g:         # the margin is below the guess
        h = hi
        while True:
            h = max(h - step, h_lo)
            sc, ok = trial(h)
            if ok is not None or h <= h_lo:
                lo, s_lo = h, sc
                break
            hi, s_hi, step = h, sc, 2 * step
    x, _, _ = largest_feasible_bracketed(trial, lo, hi, True, tol=1e-4, lo_score=s_lo,
                                         hi_score=s_hi)
    return float(x)


def exact_figures(problem: Problem, K: np.ndarray, h_min: float, h_max: float, *,
                  samples: int = 5) -> tuple[float, float, float]:
    """Exact figures of the loop with gain ``K``, state delay included.

    Returns ``(delay margin, abscissa at h_max, worst abscissa on [h_min, h_max])``, each
    the worst over :func:`perturbation_set` (constant ``D``, constant delays): the margin
    is the smallest delay ``>= h_min`` with a characteristic root on the imaginary axis
    (``h_min`` if the loop is unstable there), found from the exact one-delay margin
    (:func:`.delay.delay_margin`, ``A_tau`` left out) by stepping and bisection on
    :func:`exact_abscissa`; the interval is sampled at ``samples`` equally spaced delays.

    Parameters
    ----------
    problem : Problem
        The loop (the lagged one for a design with a lag).
    K : ndarray
        The gain (``[K, 0]`` for the lagged loop).
    h_min, h_max : float
        The latency interval (s).
    samples : int
        Delays sampled on the interval (at least its two ends).
    """
    hs = np.linspace(h_min, h_max, max(2, int(samples)))
    margins, at_max, worst = [], [], []
    for D in perturbation_set(problem, K, h_max):
        A1 = problem.B @ (K + problem.E @ D @ problem.F)
        ab = [exact_abscissa(problem.A, problem.A_tau, problem.tau, A1, float(h)) for h in hs]
        at_max.append(ab[-1])
        worst.append(max(ab))
        guess = delay_margin(problem.A, A1)
        margins.append(_margin(problem, A1, float(h_min), guess))
    return float(min(margins)), float(max(at_max)), float(max(worst))


def _max_delay_synthesis(problem: Problem, h0: float, h1: float, bound: float | None,
                         tol: float) -> InputDelayResult:
    """The ``'max-delay'`` objective of :func:`design_for_latency` (at least ``h1``).

    The interval asked for first: an infeasible request fails fast.
    """
    res: InputDelayResult | None
    try:
        synthesize_input_delay(problem, h0, h1, gain_bound=bound, stop_at_first=True)
        res = max_certified_input_delay(problem, h0, gain_bound=bound, tol=tol,
                                        h_hi=max(4 * h1, 1.0))
    except (InfeasibleError, CertificateError):
        res = None
    if res is None or res.h_max < h1:
        best = ' is' if res is None else f' is {res.h_max:.4g} s (from h_min = {h0:g} s),'
        raise InfeasibleError(
            f'the latency certified for problem {problem.name!r}'
            + (f' with ||K||_2 <= {bound:g}' if bound is not None else '')
            + f'{best} below the {h1:g} s '
            'asked for. Loosen the gain bound, reduce the latency (a predictor in the '
            'tracker removes the known part of it) or shrink the interval.')
    return res


def _lagged_figures(problem: Problem, K: np.ndarray, h0: float, h1: float, T: float,
                    tol: float) -> tuple[float, float, float, float]:
    """Exact figures and certified latency of ``K`` on the loop with the actuator lag ``T``.

    Returns ``(true margin, abscissa at h1, worst abscissa, certified h_max)``; raises
    ``InfeasibleError`` if ``[h0, h1]`` itself is not certified with the lag.
    """
    lp = lagged_problem(problem, T)
    K_aug = np.hstack([K, np.zeros((problem.m, problem.m))])
    margin, absc, worst = exact_figures(lp, K_aug, h0, h1)
    hi = min(margin, max(4 * h1, 1.0))
    guess = GUESS_OF_MARGIN * hi
    # [h0, guess] certified (monotone in h_max) implies the [h0, h1] asked for: one
    # solve decides both when the guess holds, the search then starts from there
    start = certify_input_delay(lp, K_aug, h0, guess) if guess > h1 + tol else None
    if start is None or not start.certified:
        start, guess = certify_input_delay(lp, K_aug, h0, h1), h1
    if not start.certified:
        raise InfeasibleError(
            f'the gain designed for problem {problem.name!r} is not certified with the '
            f'actuator lag {T:g} s on [{h0:g}, {h1:g}] s; try a smaller gain bound, the '
            "'max-delay' objective, or a shorter latency interval.")
    # the robot's figure: Newton steps from the guess, the slope of the strictness
    # read from the dual of the solve just made (certified_input_delay_of_gain's
    # Notes): on the paper's loops one more solve, landing above the 7-solve bracketed
    # search's figure (0.1485 / 0.2208 s against 0.1484 / 0.2206 s)
    lag_h = certified_input_delay_of_gain(
        lp, K_aug, h0, h_hi=max(hi, guess + tol), tol=0.5 * tol, h_certified=guess,
        certified_margin=start.margin_achieved, certified_slope=start.slope,
        h_hi_refuted=hi == margin > guess,
        h_guess=None if guess > h1 else GUESS_OF_MARGIN * hi)
    return margin, absc, worst, max(_settled_latency(lp, K_aug, h0, lag_h, hi), h1)


#: Significant digits of the figures a design records (decay rate, certified latency): the
#: largest value of that grid which is certified (:func:`.search.settle_on_grid`), so that
#: every machine records the same figure.  The searches stop within 0.2 % of the boundary
#: at a point that moves with the solver's last digits (0.7163 against 0.7167 1/s under
#: two OpenBLAS kernels); whether a fixed value is certified moves only when it lies that
#: close to the boundary at a fixed ``eps`` (which moves by about 1e-4 1/s between kernels:
#: the strictness ``t`` at 0.716 1/s was 2.9e-4 / 3.1e-4 / 3.0e-4 under three kernels).
FIGURE_DIGITS = 3


def _settled_decay(problem: Problem, h0: float, h1: float, bound: float | None,
                   res: InputDelayResult) -> tuple[float, InputDelayResult]:
    """The largest certified decay rate of :data:`FIGURE_DIGITS` digits and its synthesis.

    Where the grid rate itself fails, the synthesis at the search's rate (which implies it).
    """
    if not res.alpha > 0:
        return res.alpha, res

    def trial(a: float) -> InputDelayResult | None:
        try:
            # one solve at the search's eps (its last climb chose it at the boundary)
            return synthesize_input_delay(problem, h0, h1, alpha=a, gain_bound=bound,
                                          eps=res.eps)
        except (InfeasibleError, CertificateError, SolverFailure):
            return None

    rate, out, _ = settle_on_grid(trial, res.alpha, res, resolution(res.alpha, FIGURE_DIGITS))
    return rate, out


def _settled_latency(problem: Problem, K: np.ndarray, h0: float, h: float,
                     hi: float) -> float:
    """The largest certified latency ``h_max`` of :data:`FIGURE_DIGITS` digits for ``K``.

    From a search's certified ``h``, never above ``hi`` (the exact margin or cap).
    """
    if not h > max(h0, 0.0):
        return h

    def trial(x: float) -> bool | None:
        return True if certify_input_delay(problem, K, h0, x).certified else None

    x, _, _ = settle_on_grid(trial, h, True, resolution(h, FIGURE_DIGITS), hi_limit=hi)
    return x if x >= h0 else h


def design_for_latency(problem: Problem, h_min: float, h_max: float, *,
                       gain_bound: float | None = None, objective: str = 'decay',
                       lag: float = 0.0, tol: float = 2e-3) -> LatencyDesign:
    """A gain certified for command latencies in ``[h_min, h_max]``, with its figures.

    Parameters
    ----------
    problem : Problem
        Plant ``A, B``, perturbation ``E, F`` (and state delay ``A_tau, tau``).
    h_min, h_max : float
        Latency interval (s) the gain must be certified for.
    gain_bound : float, optional
        ``||K||_2`` bound (default ``problem.options['gain_bound']``, if any).
    objective : {'decay', 'max-delay'}
        ``'decay'``: largest certified decay rate on ``[h_min, h_max]``;
        ``'max-delay'``: largest certified ``h_max`` (at least the one asked for).
    lag : float
        First-order actuator time constant (s); 0 for none.
    tol : float
        Bisection tolerance for the certified ``h_max`` (s).

    Raises
    ------
    InputError
        Bad numbers or objective.
    InfeasibleError
        Nothing certifies the interval (with the lag, if given).
    """
    h0 = as_finite_float(h_min, 'h_min', low=0.0)
    h1 = as_finite_float(h_max, 'h_max', low=0.0, low_inclusive=False)
    if h0 > h1:
        raise InputError(f'delay interval must have h_min <= h_max, got [{h_min!r}, {h_max!r}]')
    T = as_finite_float(lag, 'lag', low=0.0)
    if objective not in OBJECTIVES:
        raise InputError(f'objective must be one of {OBJECTIVES}, got {objective!r}')
    bound = problem.options.get('gain_bound') if gain_bound is None else gain_bound
    if bound is not None:
        bound = as_finite_float(bound, 'gain bound', low=0.0, low_inclusive=False)
    syn_h1 = h1 + T
    res: InputDelayResult
    if objective == 'decay':
        res = max_input_delay_decay_rate(problem, h0, syn_h1, gain_bound=bound)
        decay, res = _settled_decay(problem, h0, syn_h1, bound, res)
    else:
        res = _max_delay_synthesis(problem, h0, syn_h1, bound, tol)
        decay = 0.0
    # the certified h_max of the loop without the lag.  Without a lag: searched, bracketed
    # between the synthesis' own verified interval and the exact margin (a certificate
    # never exceeds it).  With a lag it is not a figure of the robot: the synthesis'
    # verified h_max + lag is recorded (the study's region for cases without a lag)
    if objective == 'decay' and T == 0:
        margin, absc, worst = exact_figures(problem, res.K, h0, h1)
        hi = min(margin, max(4 * h1, 1.0))
        certified = certified_input_delay_of_gain(
            problem, res.K, h0, h_hi=max(hi, syn_h1 + tol), tol=tol, h_certified=syn_h1,
            h_hi_refuted=hi == margin > syn_h1, h_guess=GUESS_OF_MARGIN * hi)
        certified = max(_settled_latency(problem, res.K, h0, certified, hi), syn_h1)
    elif objective == 'decay':
        certified = syn_h1
    else:
        certified = res.h_max
    lag_h = None
    if T == 0 and objective != 'decay':
        margin, absc, worst = exact_figures(problem, res.K, h0, h1)
    if T > 0:
        margin, absc, worst, lag_h = _lagged_figures(problem, res.K, h0, h1, T, tol)
    return LatencyDesign(problem=problem.name, objective=objective, K=res.K, gain_bound=bound,
                         h_min=h0, h_max=h1, lag=T, certified_h_max=float(certified),
                         decay_rate=float(decay), lag_certified_h_max=lag_h,
                         true_delay_margin=margin, abscissa_at_h_max=absc,
                         state_delay=res.state_delay, synthesis=res, worst_abscissa=worst)


def latency_figures(problem: Problem, K: Any, *, tol: float = 2e-3, h_hi: float = 2.0
                    ) -> dict[str, float]:
    """Command-latency figures of any gain ``K`` (e.g. a Theorem 1 design).

    ``certified_latency``: largest ``h_max`` with ``[0, h_max]`` certified by
    :func:`.input_delay.certify_input_delay` (non-fragile, state delay included when
    ``A_tau != 0``); ``true_latency_margin``: exact delay margin of the input-delay loop,
    minimum over :func:`perturbation_set` (constant delay and ``D``, ``A_tau`` left out).

    Parameters
    ----------
    problem : Problem
        The loop.
    K : array_like, shape (m, n)
        The gain.
    tol : float, optional
        Absolute tolerance of ``certified_latency`` (s).
    h_hi : float, optional
        Largest latency tried (s).

    Returns
    -------
    dict
        ``certified_latency`` and ``true_latency_margin`` (s).
    """
    K = problem.gain(K)
    margin = min(delay_margin(problem.A, problem.B @ (K + problem.E @ D @ problem.F))
                 for D in perturbation_set(problem, K))
    cert = certified_input_delay_of_gain(problem, K, 0.0, tol=tol, h_hi=h_hi)
    return {'certified_latency': float(cert), 'true_latency_margin': float(margin)}


@dataclass(frozen=True)
class LatencyPlan:
    """What to certify and what the tracker predicts, derived from an identification.

    The one rule (doc/tutorial.md, "From the range to h_min, h_max"), with ``[R_lo, R_hi]`` the
    range the command-to-motion latency varies over (the identification's
    ``latency_range_s``: per-command latencies, widened to contain the interval of the
    mean; the interval of the mean alone when the range was not measured), ``[a_lo, a_hi]``
    the age of the newest odometry when a command is sent (0 when the recorded commands
    were not driven by odometry), ``T`` the command period and ``tau_v``, ``tau_w`` the
    identified lags:

    * with the predictor (default): the tracker predicts ``predict_latency = R_lo``,
      ``predict_odom_latency = a_lo`` and the lags, so that the residual delay
      ``h = (L + a) - (R_lo + a_lo)`` is never negative; certify ``h`` in
      ``[0, (R_hi - R_lo) + (a_hi - a_lo) + T]`` (``T``: the sample-and-hold);
    * without it: certify ``h`` in ``[R_lo + a_lo, R_hi + a_hi + T]``;

    and in both cases design with the actuator lag ``max(tau_v, tau_w)``.

    Why the prediction sits at the LOW end of the range, not at its middle: the
    certificate (:func:`.input_delay.certify_input_delay`) is for the loop
    ``x' = A x + B K x(t - h(t))`` with ``0 <= h_min <= h(t) <= h_max``; its
    Lyapunov-Krasovskii functional integrates the state over ``[t - h_max, t]``.  A
    command computed from the state predicted ``P`` ahead and acting after the actual
    latency ``L`` has the residual ``h = L - P``.  When ``L < P`` (over-prediction) the
    command acts on a predicted *future* state, ``u(t) = K x(t + (P - L))``: an
    anticipation, not a delay, which no interval of the certificate contains (its
    functional has no term for the future; the LMI is not even defined for ``h < 0``).
    So the over-prediction side is not certified by the design, and the prediction must
    be the lowest latency the base shows: ``P = R_lo``.  The price is that the residual
    spans the whole width of the range (``R_hi - R_lo``) rather than half of it.  A
    latency below ``R_lo`` at run time breaks this; the identified range is widened to
    contain the interval of the mean for that reason.

    The acceleration limits identified (0 = not seen to bind: unknown) go to the
    tracker's ``max_linear_accel`` and ``max_angular_accel``.

    The static channel gains identified (``gain_v``, ``gain_w`` with their intervals; 1 and
    NaN when not identified, e.g. read from a file) go to the tracker's ``gain_v``,
    ``gain_w`` when they matter (:data:`GAIN_COMPENSATED`: the interval excludes 1 and the
    gain is more than 2 % from it; a skid-steer's turn gain): the tracker then divides its
    commands by them.  The design's certificate is for the compensated loop with unit gain;
    what is left of a turn gain's uncertainty (its interval over the gain, a multiplicative
    input uncertainty) is decided by :func:`gain_verdict`, a speed gain's is not covered.
    """

    predictor: bool
    h_min: float
    h_max: float
    lag: float
    predict_latency: float
    predict_odom_latency: float
    predict_lag_v: float
    predict_lag_w: float
    latency_interval: tuple[float, float]
    command_age: tuple[float, float]
    command_period: float
    source: str
    latency_range: tuple[float, float] = (math.nan, math.nan)
    latency_range_from: str = ''
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    commands_follow_odometry: bool | None = None
    #: The identified static gains of the speed and of the turn rate.
    gains: tuple[float, float] = (1.0, 1.0)
    #: Their intervals, low and high each (NaN: not identified).
    gain_intervals: tuple[tuple[float, float], tuple[float, float]] = (
        (math.nan, math.nan), (math.nan, math.nan))
    #: The side-slip table identified (rad/s, s; empty: none), compensated as it is.
    side_slip_rates: tuple[float, ...] = ()
    side_slip: tuple[float, ...] = ()

    def slip_parameters(self) -> dict[str, list[float]]:
        """The tracker's ``side_slip_rates`` / ``side_slip`` (empty without a table).

        Returns
        -------
        dict
        """
        if not self.side_slip:
            return {}
        return {'side_slip_rates': list(self.side_slip_rates),
                'side_slip': list(self.side_slip)}

    def gain_parameters(self) -> dict[str, float]:
        """The tracker's ``gain_v`` / ``gain_w`` for the gains that matter (see the class).

        Returns
        -------
        dict
            ``{'gain_w': 0.64}`` for a skid-steer; empty when no gain needs compensating.
        """
        out = {}
        for name, g, (lo, hi) in zip(('gain_v', 'gain_w'), self.gains, self.gain_intervals):
            if math.isfinite(g) and g > 0 and abs(g - 1.0) > GAIN_COMPENSATED \
                    and math.isfinite(lo) and math.isfinite(hi) and not lo <= 1.0 <= hi:
                out[name] = float(g)
        return out

    def tracker_parameters(self) -> dict[str, float]:
        """The tracker's predictor parameters this plan assumes (all 0 without predictor)."""
        keys = ('predict_latency', 'predict_odom_latency', 'predict_lag_v', 'predict_lag_w')
        if not self.predictor:
            return {k: 0.0 for k in keys}
        return {k: float(getattr(self, k)) for k in keys}

    def actuator_parameters(self) -> dict[str, float]:
        """The tracker's acceleration limits the identification found (with or without predictor).

        ``max_linear_accel`` in m/s^2, ``max_angular_accel`` in rad/s^2.  A limit the
        recording did not show binding (0 = unknown) is left out: the gain file's tracker
        section overrides the robot's parameter file, and a 0 there would switch off a limit
        the user knows (and the re-timing and rate limiting that come with it).
        """
        found = {'max_linear_accel': float(self.max_linear_accel),
                 'max_angular_accel': float(self.max_angular_accel)}
        return {k: v for k, v in found.items() if v > 0.0}

    def metadata(self) -> dict[str, Any]:
        """Flat record for the gain file's design section."""
        out: dict[str, Any] = {
            'designed_from': self.source or '(identification)',
            'compensation': 'predictor' if self.predictor else 'none',
            'identified_latency_interval': list(self.latency_interval),
            'identified_latency_range': list(self.latency_range),
            'identified_command_age': list(self.command_age),
            'command_period': self.command_period,
            **{k: v for k, v in self.tracker_parameters().items()},
            'max_linear_accel': float(self.max_linear_accel),      # 0 = unknown
            'max_angular_accel': float(self.max_angular_accel)}
        for name, g, iv in zip(('v', 'w'), self.gains, self.gain_intervals):
            if math.isfinite(g):
                out[f'identified_gain_{name}'] = float(g)
                out[f'identified_gain_{name}_interval'] = [float(iv[0]), float(iv[1])]
        out.update({f'compensated_{k}': v for k, v in self.gain_parameters().items()})
        out.update({f'compensated_{k}': v for k, v in self.slip_parameters().items()})
        if self.latency_range_from:
            out['latency_range_from'] = self.latency_range_from
        return out

    def describe(self) -> str:
        """One line per derived quantity."""
        lo, hi = self.latency_interval
        r0, r1 = self.latency_range
        a0, a1 = self.command_age
        origin = self.latency_range_from or 'the interval of the mean'
        head = (f'identified latency: mean in [{lo:.4f}, {hi:.4f}] s (uncertainty of the mean); '
                f'varies over [{r0:.4f}, {r1:.4f}] s (from {origin}: the range certified)\n')
        if self.commands_follow_odometry is False:
            head += ('command age: not counted (the recorded commands were not driven by the '
                     'odometry; the tracker\'s own odometry-to-command time is not in this '
                     'recording)')
        else:
            head += f'command age [{a0:.4f}, {a1:.4f}] s'
        head += f', command period {self.command_period:.4g} s, lag {self.lag:.4f} s'
        if self.max_linear_accel or self.max_angular_accel:
            head += (f'\nacceleration limits: max_linear_accel {self.max_linear_accel:.4g} m/s^2, '
                     f'max_angular_accel {self.max_angular_accel:.4g} rad/s^2 (0 = unknown)')
        for name, g in self.gain_parameters().items():
            lo, hi = self.gain_intervals[name == 'gain_w']
            head += (f'\nchannel gain: {name} = {g:.4f} (interval [{lo:.4f}, {hi:.4f}]), '
                     'compensated (the command is divided by it); the design\'s certificate '
                     'takes it as exact: the rest of its uncertainty '
                     f'(+-{100 * max(hi - g, g - lo) / g:.2f} %) is decided apart '
                     '(gain_verdict)')
        if self.side_slip:
            head += ('\nside slip: ' + ', '.join(
                f'c({r:g} rad/s) = {c:.4f} s' for r, c in zip(self.side_slip_rates,
                                                              self.side_slip))
                     + ' (the tracker adds the slide to the odometry\'s position; not in the '
                     'certificate: a correction of the measurement)')
        if self.predictor:
            return (head + f'\npredictor: predict_latency = {self.predict_latency:.4f} s (low end '
                    f'of the range: the residual delay stays >= 0), predict_odom_latency = '
                    f'{self.predict_odom_latency:.4f} s, predict_lag_v = {self.predict_lag_v:.4f} '
                    f's, predict_lag_w = {self.predict_lag_w:.4f} s'
                    f'\nresidual delay to certify: [{self.h_min:.4f}, {self.h_max:.4f}] s')
        return head + (f'\nno predictor: delay to certify [{self.h_min:.4f}, '
                       f'{self.h_max:.4f}] s')


def delay_interval(latency_lo: float, latency_hi: float, *, predictor: bool,
                   command_period: float, age: tuple[float, float] = (0.0, 0.0)
                   ) -> tuple[float, float]:
    """The delay interval to certify for a latency interval (the one rule, :class:`LatencyPlan`).

    Parameters
    ----------
    latency_lo, latency_hi : float
        Command-to-motion latency interval ``[L_lo, L_hi]`` (s).
    predictor : bool
        With the tracker's predictor at ``L_lo + a_lo``: the residual
        ``[0, (L_hi - L_lo) + (a_hi - a_lo) + T]``; without: ``[L_lo + a_lo, L_hi + a_hi + T]``.
    command_period : float
        The command period ``T`` (sample and hold), s.
    age : (float, float)
        Odometry age ``[a_lo, a_hi]`` when a command is sent (s).
    """
    lo, hi, T = float(latency_lo), float(latency_hi), float(command_period)
    a_lo, a_hi = float(age[0]), float(age[1])
    if predictor:
        return 0.0, (hi - lo) + (a_hi - a_lo) + T
    return lo + a_lo, hi + a_hi + T


def plan_from_identification(ident: Identification, *, predictor: bool = True,
                             command_period: float | None = None) -> LatencyPlan:
    """The delay interval, lag, predictor settings and limits for an identification.

    Parameters
    ----------
    ident : Identification
        From :func:`.identify.identify_latency` or :func:`.records.read_identification`.
    predictor : bool
        Design for the tracker with its predictor at the low end of the latency range
        (the residual delay) or for the uncompensated law (the whole delay).
    command_period : float, optional
        The tracker's command period ``T`` (s); default: the identification's
        ``command_period_s``, or the odometry period when the recorded commands were not
        driven by the odometry (a joystick's period is not the tracker's, which commands
        once per odometry message).  Required when the identification has neither.

    Returns
    -------
    LatencyPlan
        See the class docstring for the rule and why the prediction is the low end of
        the range (the certificate does not cover over-prediction).

    Raises
    ------
    InputError
        No command period known, or a bad one.
    """
    T = ident.command_period_s if command_period is None else command_period
    if command_period is None and ident.commands_follow_odometry is False \
            and math.isfinite(ident.odom_rate_hz) and ident.odom_rate_hz > 0:
        # a joystick's period is not the tracker's; the tracker commands once per odometry
        T = 1.0 / ident.odom_rate_hz
    if T is None or not math.isfinite(float(T)):
        raise InputError('the identification has no command_period_s (an older file or '
                         'another tool wrote it); pass the tracker\'s command period, e.g. '
                         '--command-period 0.02')
    T = as_finite_float(T, 'command period', low=0.0, low_inclusive=False)
    a_lo = ident.command_age_low_s if math.isfinite(ident.command_age_low_s) else 0.0
    a_hi = ident.command_age_high_s if math.isfinite(ident.command_age_high_s) else a_lo
    a_lo, a_hi = max(a_lo, 0.0), max(a_hi, a_lo, 0.0)
    lo, hi = ident.latency_range_s
    lag = max(ident.tau_v_s, ident.tau_w_s)
    h0, h1 = delay_interval(lo, hi, predictor=predictor, command_period=T, age=(a_lo, a_hi))
    return LatencyPlan(predictor=predictor, h_min=float(h0), h_max=float(h1), lag=float(lag),
                       predict_latency=float(lo), predict_odom_latency=float(a_lo),
                       predict_lag_v=float(ident.tau_v_s), predict_lag_w=float(ident.tau_w_s),
                       latency_interval=(float(ident.latency_low_s),
                                         float(ident.latency_high_s)),
                       command_age=(float(a_lo), float(a_hi)), command_period=float(T),
                       source=str(ident.source), latency_range=(float(lo), float(hi)),
                       latency_range_from=str(ident.latency_range_from),
                       max_linear_accel=float(ident.max_linear_accel),
                       max_angular_accel=float(ident.max_angular_accel),
                       commands_follow_odometry=ident.commands_follow_odometry,
                       gains=(float(ident.gain_v), float(ident.gain_w)),
                       gain_intervals=((float(ident.gain_v_low), float(ident.gain_v_high)),
                                       (float(ident.gain_w_low), float(ident.gain_w_high))),
                       side_slip_rates=tuple(ident.side_slip_rates),
                       side_slip=tuple(ident.side_slip))
