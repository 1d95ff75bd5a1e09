"""Everything we say about one gain ``K`` on one problem, in one record.

Used by the CLI (``analyse``, ``margins``), the paper reproduction and the
benchmarks, so the numbers they print are computed in one place.

See doc/cli.md, sections "analyse" and "margins".
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from . import delay
from .lmi import CertifyResult, certified_perturbation_scale, certify_gain
from .problem import Problem

__all__ = ['GainAnalysis', 'analyse_gain', 'format_analysis', 'certified_decay_rate']


@dataclass(frozen=True)
class GainAnalysis:
    """Certificates, delay-loop abscissae and fragility margins of a gain."""

    name: str
    K: list[list[float]]
    norm: float                          # ||K||_2
    certified_nominal: bool              # Theorem 1 with D = 0
    certified_nonfragile: bool           # Theorem 1 with E D F, ||D|| <= 1
    certify_margin: float                # best normalized strictness t of the non-fragile check
    abscissa_nominal: float              # spectral abscissa of the delay loop, D = 0
    abscissa: dict[str, float] = field(default_factory=dict)   # per named perturbation D
    worst_abscissa: float = math.nan     # worst case over ||D|| <= 1 (measured)
    measured_margin: float = math.nan    # largest scale keeping every ||D|| <= 1 stable
    certified_margin: float = math.nan   # largest scale Theorem 1 certifies
    certified_decay: float = math.nan    # largest alpha Theorem 1 certifies for this K
    delay_margin: float = math.nan       # true: smallest unstable delay, D = 0 (inf: none)
    certified_delay: float = math.nan    # inf when Theorem 1 (delay-independent) certifies K
    tau: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready dict."""
        return asdict(self)


def analyse_gain(problem: Problem, K: ArrayLike, *, name: str = 'K', margins: bool = True,
                 seed: int = 0) -> GainAnalysis:
    """Analyse ``K`` on ``problem`` (certificates, abscissae at ``problem.tau``, margins).

    Parameters
    ----------
    problem : Problem
        The plant, delay and perturbation structure (``E``, ``F``, named ``D``).
    K : array_like, shape (m, n)
        The state-feedback gain.
    name : str, optional
        The label of the gain in the record (a column of :func:`format_analysis`).
    margins : bool, optional
        Also compute the costly ones: certified decay rate, worst-case abscissa and the
        measured and certified fragility margins (``nan`` when ``False``).
    seed : int, optional
        Seed of the random starts of the worst-case perturbation search.

    Returns
    -------
    GainAnalysis
    """
    K = problem.gain(K)
    A, B, Ad, tau, E, F = problem.A, problem.B, problem.A_tau, problem.tau, problem.E, problem.F
    nom = certify_gain(problem, K, nominal=True)
    nf = certify_gain(problem, K)
    absc = {}
    for key, D in problem.perturbations.items():
        A0 = delay.closed_loop_matrix(A, B, K, E, F, D)
        absc[key] = float(delay.spectral_abscissa(A0, Ad, tau))
    A_nom = delay.closed_loop_matrix(A, B, K)
    a_nom = float(delay.spectral_abscissa(A_nom, Ad, tau))
    d_margin = float(delay.delay_margin(A_nom, Ad))
    worst = measured = certified = decay = math.nan
    if margins:
        decay = certified_decay_rate(problem, K)
        worst = float(delay.worst_case_abscissa(A, B, K, Ad, tau, E, F, seed=seed)[0])
        measured = float(delay.fragility_margin(A, B, K, Ad, tau, E, F, seed=seed).alpha)
        certified = float(certified_perturbation_scale(problem, K))
    return GainAnalysis(name=name, K=K.tolist(), norm=float(np.linalg.norm(K, 2)),
                        certified_nominal=nom.certified, certified_nonfragile=nf.certified,
                        certify_margin=float(nf.margin_achieved), abscissa_nominal=a_nom,
                        abscissa=absc, worst_abscissa=worst, measured_margin=measured,
                        certified_margin=certified, certified_decay=decay,
                        delay_margin=d_margin,
                        certified_delay=math.inf if nf.certified else math.nan, tau=tau)


def certified_decay_rate(problem: Problem, K: ArrayLike, *, hi: float = 50.0,
                         rel_tol: float = 1e-3) -> float:
    """Largest ``alpha`` with Theorem 1 (non-fragile) certifying ``K`` on the shifted problem.

    The shifted problem is (``A + alpha I``, ``e^{alpha tau} A_tau``): every
    ``||D(t)|| <= 1`` decays at least as ``e^{-alpha t}``.

    Parameters
    ----------
    problem : Problem
        The problem to shift.
    K : array_like, shape (m, n)
        The gain to certify.
    hi : float, optional
        Upper limit of the search for ``alpha`` [1/s].
    rel_tol : float, optional
        Relative tolerance of the bisection on ``alpha``.

    Returns
    -------
    float
        The certified decay rate [1/s]; 0.0 if ``K`` is not certified at all.
    """
    from .design import shifted_problem
    from .search import largest_feasible

    def trial(a: float) -> CertifyResult | None:
        try:
            res = certify_gain(shifted_problem(problem, a), K)
        except Exception:  # noqa: BLE001 - numerical trouble at an extreme trial: not certified
            return None
        return res if res.certified else None

    if trial(0.0) is None:
        return 0.0
    return largest_feasible(trial, 0.0, 0.5, rel_tol=rel_tol, hi_limit=hi)[0]


def _fmt(x: float) -> str:
    if isinstance(x, float) and math.isinf(x):
        return 'inf'
    return f'{x:.4g}'


def format_analysis(rows: list[GainAnalysis]) -> str:
    """A plain-text table, one column per gain.

    Parameters
    ----------
    rows : list of GainAnalysis
        The gains' records, in column order (the perturbation rows are those of the first).

    Returns
    -------
    str
        The table ('' for no rows).
    """
    if not rows:
        return ''
    keys = list(rows[0].abscissa)
    lines = [('', [r.name for r in rows]),
             ('||K||_2', [_fmt(r.norm) for r in rows]),
             ('Theorem 1 nominal certified',
              ['yes' if r.certified_nominal else 'no' for r in rows]),
             ('Theorem 1 non-fragile certified',
              ['yes' if r.certified_nonfragile else 'no' for r in rows]),
             (f'abscissa, D = 0 (tau = {rows[0].tau:g} s)',
              [_fmt(r.abscissa_nominal) for r in rows])]
    lines += [(f'abscissa, D = {k}', [_fmt(r.abscissa[k]) for r in rows]) for k in keys]
    lines += [('worst abscissa, ||D|| <= 1', [_fmt(r.worst_abscissa) for r in rows]),
              ('decay rate, true (worst case)', [_fmt(-r.worst_abscissa) for r in rows]),
              ('decay rate, certified', [_fmt(r.certified_decay) for r in rows]),
              ('fragility margin, measured', [_fmt(r.measured_margin) for r in rows]),
              ('fragility margin, certified', [_fmt(r.certified_margin) for r in rows]),
              ('delay margin (s), true, D = 0', [_fmt(r.delay_margin) for r in rows]),
              ('delay certified up to (s)', [_fmt(r.certified_delay) for r in rows])]
    w0 = max(len(a) for a, _ in lines)
    w = max(12, *(len(c) for _, cs in lines for c in cs))
    return '\n'.join(f'{a:<{w0}}  ' + '  '.join(f'{c:>{w}}' for c in cs) for a, cs in lines)
